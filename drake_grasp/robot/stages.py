"""Wall time by stage of the grasping pipeline, for the bench: the functions that do a stage's work are
marked `@stage("planning")`, and while a `StageClock` runs they report to it (otherwise the mark costs
one check a call).

    >>> with StageClock() as clock:
    ...     run_one(config, seed)
    >>> clock.seconds  # {"physics": 41.2, "selection": 6.3, "planning": 2.1, ...}
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from typing import TypeVar

F = TypeVar("F", bound=Callable)

_running: StageClock | None = None  # the clock the marked functions report to


class StageClock:
    """Exclusive wall seconds per stage: a stage's time leaves out the marked stages it calls (the selector
    evaluates the perception, which evaluates the camera)."""

    def __init__(self):
        self.seconds: dict[str, float] = {}
        self._stack: list[list] = []  # [stage, start, seconds claimed by the stages inside]
        self._outer: StageClock | None = None

    def __enter__(self) -> StageClock:
        global _running
        self._outer, _running = _running, self
        return self

    def __exit__(self, *exc) -> None:
        global _running
        _running = self._outer

    def _start(self, name: str) -> list:
        frame = [name, time.perf_counter(), 0.0]
        self._stack.append(frame)
        return frame

    def _stop(self, frame: list) -> None:
        self._stack.pop()
        spent = time.perf_counter() - frame[1]
        self.seconds[frame[0]] = self.seconds.get(frame[0], 0.0) + spent - frame[2]
        if self._stack:
            self._stack[-1][2] += spent


def stage(name: str) -> Callable[[F], F]:
    """Marks a function as stage `name`'s work (see the module's docstring)."""
    def mark(fn: F) -> F:
        @functools.wraps(fn)
        def timed(*args, **kwargs):
            clock = _running
            if clock is None:
                return fn(*args, **kwargs)
            frame = clock._start(name)
            try:
                return fn(*args, **kwargs)
            finally:
                clock._stop(frame)

        return timed  # type: ignore[return-value]

    return mark
