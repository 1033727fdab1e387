"""The memory allocator the programs run with: tcmalloc (or jemalloc) when the machine has it.

Drake's contact solve allocates and frees many small blocks every step; with glibc's allocator
about a fifth of a closed-loop run is spent in malloc and free. Run under tcmalloc, a standard run
takes about three quarters of the time with the very same attempts (an allocator changes where
memory lies, never a number the simulation computes). An allocator must be chosen before the
process starts, so a program started from the command line (`run_with_fast_allocator`, called first
thing by the entry points) starts itself once more with the library in `LD_PRELOAD`; the worker
processes it spawns inherit it. `scripts/setup.sh` installs Debian's `libtcmalloc-minimal4`.

`DRAKE_GRASP_ALLOCATOR=system` keeps the system's allocator.
"""

from __future__ import annotations

import ctypes.util
import os
import sys

ALLOCATOR_VARIABLE = "DRAKE_GRASP_ALLOCATOR"  # "system": do not preload a faster allocator
FAST_ALLOCATORS = ("tcmalloc_minimal", "jemalloc")  # library names, in order of preference
# tcmalloc reports every allocation over 1 GiB on stderr; training data sets may take more.
QUIET_TCMALLOC = {"TCMALLOC_LARGE_ALLOC_REPORT_THRESHOLD": str(1 << 45)}


def fast_allocator() -> str | None:
    """The file name of the first of `FAST_ALLOCATORS` the dynamic loader finds (Linux), or None."""
    if not sys.platform.startswith("linux"):
        return None
    for name in FAST_ALLOCATORS:
        library = ctypes.util.find_library(name)
        if library:
            return library
    return None


def preloaded_allocator() -> str | None:
    """The faster allocator this process runs with (in `LD_PRELOAD`), or None: the system's."""
    preload = os.environ.get("LD_PRELOAD", "")
    return next((entry for entry in preload.split(":") if any(n in entry for n in FAST_ALLOCATORS)), None)


def run_with_fast_allocator() -> None:
    """Starts this program again with a faster allocator preloaded, unless it runs with one already, the
    machine has none, or `DRAKE_GRASP_ALLOCATOR=system`. Returns only when it does not."""
    if os.environ.get(ALLOCATOR_VARIABLE) == "system" or preloaded_allocator() is not None:
        return
    library = fast_allocator()
    if library is None or not getattr(sys, "orig_argv", None):
        return
    preload = ":".join(filter(None, [library, os.environ.get("LD_PRELOAD", "")]))
    env = {**QUIET_TCMALLOC, **os.environ, "LD_PRELOAD": preload}
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(sys.executable, [sys.executable, *sys.orig_argv[1:]], env)
