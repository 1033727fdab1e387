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


def non_negative_int(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be zero or positive, got {text}")
    return value


def fraction(text: str) -> float:
    value = float(text)
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"must lie strictly between 0 and 1, got {text}")
    return value


def positive_ints(text: str) -> list[int]:
    """A comma-separated list of positive integers."""
    try:
        return [positive_int(item) for item in text.split(",")]
    except (ValueError, argparse.ArgumentTypeError):
        message = f"expected positive integers separated by commas, got {text!r}"
        raise argparse.ArgumentTypeError(message) from None


def quiet_drake() -> None:
    """Drake's INFO lines (context parallelism and the like) are noise for our users."""
    logging.getLogger("drake").setLevel(logging.WARNING)
