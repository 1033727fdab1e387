"""`python -m drake_grasp.detect`: the program in `drake_grasp.apps.detect`."""

import sys

from drake_grasp.apps.detect import main

if __name__ == "__main__":
    sys.exit(main())
