"""`python -m drake_grasp.rp_report`: the program in `drake_grasp.apps.rp_report`."""

import sys

from drake_grasp.apps.rp_report import main

if __name__ == "__main__":
    sys.exit(main())
