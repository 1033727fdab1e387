"""`python -m drake_grasp.grasp_threshold`: the program in `drake_grasp.apps.grasp_threshold`."""

import sys

from drake_grasp.apps.grasp_threshold import main

if __name__ == "__main__":
    sys.exit(main())
