"""What the notebooks in `notebooks/` share: test mode.

CI executes every notebook top to bottom with the environment variable
`DRAKE_GRASP_NOTEBOOK_TEST=1`; a notebook then shrinks its loops, scenes and
simulated time through `size(full, test)`, as the Drake and manipulation-course
notebooks do with `running_as_notebook`.
"""

from __future__ import annotations

import os
from typing import TypeVar

from drake_grasp.robot.log import program_logging  # noqa: F401  (for the notebooks)

TEST_MODE_VARIABLE = "DRAKE_GRASP_NOTEBOOK_TEST"
T = TypeVar("T")


def test_mode() -> bool:
    """Whether the notebook runs in CI's small test mode."""
    return os.environ.get(TEST_MODE_VARIABLE, "").strip().lower() not in ("", "0", "false", "no")


def size(full: T, test: T) -> T:
    """`full` for a reader, `test` in test mode."""
    return test if test_mode() else full
