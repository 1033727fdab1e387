"""`python -m drake_grasp.collect_reachability`: the program in `drake_grasp.apps.collect_reachability`."""

import sys

from drake_grasp.apps.allocator import run_with_fast_allocator

if __name__ == "__main__":
    run_with_fast_allocator()
    from drake_grasp.apps.collect_reachability import main

    sys.exit(main())
