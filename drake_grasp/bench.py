"""`python -m drake_grasp.bench`: the program in `drake_grasp.apps.bench`."""

import sys

from drake_grasp.apps.bench import main

if __name__ == "__main__":
    sys.exit(main())
