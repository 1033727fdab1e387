"""`python -m drake_grasp.simulate`: the program in `drake_grasp.apps.simulate`."""

import sys

from drake_grasp.apps.allocator import run_with_fast_allocator

if __name__ == "__main__":
    run_with_fast_allocator()
    from drake_grasp.apps.simulate import main

    sys.exit(main())
