"""`python -m drake_grasp.compare_detect`: the program in `drake_grasp.apps.compare_detect`."""

import sys

from drake_grasp.apps.compare_detect import main

if __name__ == "__main__":
    sys.exit(main())
