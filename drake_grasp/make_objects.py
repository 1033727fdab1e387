"""`python -m drake_grasp.make_objects`: the program in `drake_grasp.apps.make_objects`."""

import sys

from drake_grasp.apps.make_objects import main

if __name__ == "__main__":
    sys.exit(main())
