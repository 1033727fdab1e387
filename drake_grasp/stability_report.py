"""`python -m drake_grasp.stability_report`: the program in `drake_grasp.apps.stability_report`."""

import sys

from drake_grasp.apps.stability_report import main

if __name__ == "__main__":
    sys.exit(main())
