"""`python -m drake_grasp.train`: the program in `drake_grasp.apps.train`."""

import sys

from drake_grasp.apps.train import main

if __name__ == "__main__":
    sys.exit(main())
