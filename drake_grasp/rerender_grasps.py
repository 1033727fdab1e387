"""`python -m drake_grasp.rerender_grasps`: the program in `drake_grasp.apps.rerender_grasps`."""

import sys

from drake_grasp.apps.rerender_grasps import main

if __name__ == "__main__":
    sys.exit(main())
