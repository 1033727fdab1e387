"""`python -m drake_grasp.compare_trials`: the program in `drake_grasp.apps.compare_trials`."""

import sys

from drake_grasp.apps.compare_trials import main

if __name__ == "__main__":
    sys.exit(main())
