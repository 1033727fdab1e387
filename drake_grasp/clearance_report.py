"""`python -m drake_grasp.clearance_report`: the program in `drake_grasp.apps.clearance_report`."""

import sys

from drake_grasp.apps.clearance_report import main

if __name__ == "__main__":
    sys.exit(main())
