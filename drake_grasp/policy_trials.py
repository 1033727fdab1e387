"""`python -m drake_grasp.policy_trials`: the program in `drake_grasp.apps.policy_trials`."""

import sys

from drake_grasp.apps.policy_trials import main

if __name__ == "__main__":
    sys.exit(main())
