#!/usr/bin/env bash
# Sets up drake_grasp on a fresh machine: Debian's libusb-1.0-0 (open3d needs it), optionally
# libtcmalloc-minimal4 (a faster allocator the programs preload), a virtual environment in .venv,
# and the pinned Python packages. Safe to rerun: it does nothing when everything is in place.
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON=${PYTHON:-python3.11}
command -v "$PYTHON" >/dev/null 2>&1 || PYTHON=python3
if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
  echo "error: drake_grasp needs Python 3.11 (found $("$PYTHON" --version 2>&1)); set PYTHON=/path/to/python3.11" >&2
  exit 2
fi

# has_library SONAME: whether the dynamic loader knows the library. can_apt: root with apt-get.
has_library() { ldconfig -p 2>/dev/null | grep -q "$1"; }
can_apt() { [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; }
apt_install() { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$1" >/dev/null; }

if ! has_library 'libusb-1.0.so.0'; then
  if can_apt; then
    echo "setup: installing libusb-1.0-0 (needed by open3d)"
    apt_install libusb-1.0-0
  else
    echo "error: open3d needs the system library libusb-1.0 (Debian/Ubuntu: sudo apt-get install libusb-1.0-0)" >&2
    exit 2
  fi
fi

# Optional: tcmalloc, which the programs preload (closed-loop runs take about three quarters of the time).
if ! has_library 'libtcmalloc_minimal.so'; then
  if can_apt; then
    echo "setup: installing libtcmalloc-minimal4 (a faster memory allocator for the simulation)"
    apt_install libtcmalloc-minimal4 \
      || echo "setup: libtcmalloc-minimal4 could not be installed; the programs use the system allocator"
  else
    echo "setup: optional: 'sudo apt-get install libtcmalloc-minimal4' makes simulation about 1.3x faster"
  fi
fi

[ -x .venv/bin/python ] || "$PYTHON" -m venv .venv
stamp=.venv/.drake_grasp-installed
want=$(sha256sum pyproject.toml | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "setup: installing Python packages into .venv (first time: a few minutes)"
  .venv/bin/python -m pip install -q --upgrade pip
  # torch first and pinned: an unpinned torch would pull the CUDA build (several GB).
  .venv/bin/python -m pip install -q "torch==2.13.0"
  .venv/bin/python -m pip install -q -e ".[dev]"
  echo "$want" > "$stamp"
fi
