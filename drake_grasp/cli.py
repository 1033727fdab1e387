"""Small helpers shared by the command-line entry points."""

from __future__ import annotations

import argparse
import logging
import sys


def fail(error: Exception | str) -> int:
    """Prints a one-line error naming the problem; returns the CLI exit code 2."""
    message = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
    print(f"error: {message}", file=sys.stderr)
    return 2


def positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def quiet_drake() -> None:
    """Drake's INFO lines (context parallelism and the like) are noise for our users."""
    logging.getLogger("drake").setLevel(logging.WARNING)
