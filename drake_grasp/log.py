"""Logging defaults for programs, workers and notebooks."""

import logging


def quiet_drake() -> None:
    """Drake's INFO lines (context parallelism and the like) are noise for our users."""
    logging.getLogger("drake").setLevel(logging.WARNING)
