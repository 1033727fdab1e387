"""`python -m drake_grasp.collect_grasps`: the program in `drake_grasp.apps.collect_grasps`."""

import sys

from drake_grasp.apps.collect_grasps import main

if __name__ == "__main__":
    sys.exit(main())
