"""A simulation that diverges is a recorded outcome, not a crash.

A violent contact (a rigid body squeezed between rigid fingers, a stiff object
dropped on another) can make a discrete step blow up: Drake then raises a
RuntimeError naming a non-finite value or a solver that did not converge. The trial
or run in which it happens ends with `DIVERGED` as its reason; the job goes on.
"""

from __future__ import annotations

from drake_grasp.robot.task import DIVERGED

__all__ = ["DIVERGED", "first_line", "is_divergence"]

DIVERGENCE_WORDS = ("non-finite value", "failed to converge", "NaN", "infinit")  # in Drake's messages


def is_divergence(error: BaseException) -> bool:
    """Whether Drake raised because the simulation diverged."""
    return isinstance(error, RuntimeError) and any(words in str(error) for words in DIVERGENCE_WORDS)


def first_line(error: BaseException | str) -> str:
    """The error's (or message's) first line, for a report or a log."""
    text = str(error).strip()
    return text.splitlines()[0] if text else type(error).__name__
