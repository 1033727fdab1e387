"""`python -m drake_grasp.evaluate_cnn`: the program in `drake_grasp.apps.evaluate_cnn`."""

import sys

from drake_grasp.apps.evaluate_cnn import main

if __name__ == "__main__":
    sys.exit(main())
