"""`python -m drake_grasp.record_grasp`: the program in `drake_grasp.apps.record_grasp`."""

import sys

from drake_grasp.apps.record_grasp import main

if __name__ == "__main__":
    sys.exit(main())
