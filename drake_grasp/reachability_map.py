"""`python -m drake_grasp.reachability_map`: the program in `drake_grasp.apps.reachability_map`."""

import sys

from drake_grasp.apps.reachability_map import main

if __name__ == "__main__":
    sys.exit(main())
