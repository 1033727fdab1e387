"""`python -m drake_grasp.collect_reachability`: the program in `drake_grasp.apps.collect_reachability`."""

import sys

from drake_grasp.apps.collect_reachability import main

if __name__ == "__main__":
    sys.exit(main())
