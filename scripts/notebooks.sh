#!/usr/bin/env bash
# Sets up drake_grasp (scripts/setup.sh), adds JupyterLab, and opens the notebooks.
# Meshcat's URL is printed by each notebook's first cell.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/python -c "import jupyterlab" 2>/dev/null || .venv/bin/python -m pip install -q -e ".[notebooks]"
exec .venv/bin/jupyter lab notebooks/ "$@"
