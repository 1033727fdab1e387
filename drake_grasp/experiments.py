"""`python -m drake_grasp.experiments`: the program in `drake_grasp.apps.experiments`."""

import sys

from drake_grasp.apps.experiments import main

if __name__ == "__main__":
    sys.exit(main())
