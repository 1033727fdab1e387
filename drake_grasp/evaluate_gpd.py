"""`python -m drake_grasp.evaluate_gpd`: the program in `drake_grasp.apps.evaluate_gpd`."""

import sys

from drake_grasp.apps.evaluate_gpd import main

if __name__ == "__main__":
    sys.exit(main())
