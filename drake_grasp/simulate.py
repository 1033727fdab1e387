"""`python -m drake_grasp.simulate`: the program in `drake_grasp.apps.simulate`."""

import sys

from drake_grasp.apps.simulate import main

if __name__ == "__main__":
    sys.exit(main())
