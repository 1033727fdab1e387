"""`python -m drake_grasp <command>`: the programs of `drake_grasp.apps.commands`."""

import sys

from drake_grasp.apps.commands import main

if __name__ == "__main__":
    sys.exit(main())
