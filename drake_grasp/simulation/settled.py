"""Settled scenes kept for the next run of the same scene: a table's policies share each seed's drop.

Dropping a seeded scene's objects and letting them settle is the same physics whatever
policy then grasps in it, and in a challenging run (30 objects falling at once) it is about a
tenth of the run. `SettledScenes` keeps the state the settle ends in (the simulation time and
the diagram's discrete state: every body's pose and velocity) in a folder, under a key of
everything the drop depends on (`scene_key`: the arm, the scenario's drop and physics, the
objects chosen, the seed; not what acts only once the scene is observed, such as the cameras).
A run whose scene is there sets that state instead of simulating the drop, and runs attempt for
attempt as the run that settled it (`tests/test_settled.py`).

The folder is meant to live as long as one job (`experiments` makes a temporary one): a key
names inputs, not the code that settles, so states kept across code changes could be stale.
"""

from __future__ import annotations

import dataclasses as dc
import hashlib
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.systems.framework import Context

from drake_grasp.robot.specs import RobotSpec
from drake_grasp.simulation.objects import ObjectModel
from drake_grasp.simulation.scenario import Scenario


@dataclass(frozen=True)
class SettledState:
    """Where a settle ends: the time and each discrete state group of the root context."""

    time: float
    discrete: tuple[np.ndarray, ...]

    @staticmethod
    def of(context: Context) -> SettledState:
        """The state of `context` (a root context)."""
        if context.num_continuous_states():
            raise ValueError("a settled scene is kept for discrete (time-stepping) plants only")
        return SettledState(context.get_time(), tuple(context.get_discrete_state(i).CopyToVector()
                                                      for i in range(context.num_discrete_state_groups())))

    def apply(self, context: Context) -> None:
        """Sets the time and the discrete state of `context` (the root context of the same diagram)."""
        sizes = [context.get_discrete_state(i).size() for i in range(context.num_discrete_state_groups())]
        if [len(values) for values in self.discrete] != sizes:
            raise ValueError("the settled state belongs to another diagram")
        context.SetTime(self.time)
        for i, values in enumerate(self.discrete):
            context.SetDiscreteState(i, values)


# Scenario fields that act only once the settled scene is observed: scenes that differ in these alone
# settle the same (a policy's second camera, the top-grasping variant's approach angles). Every other field
# is part of the key, a field added later included.
AFTER_THE_DROP = ("name", "sensing", "sampling", "retreat_before_lift", "max_consecutive_failures",
                  "max_consecutive_plan_failures", "max_attempts")


def scene_key(robot: RobotSpec, scenario: Scenario, objects: Sequence[ObjectModel], seed: int) -> str:
    """A name for everything a seeded scene's drop depends on."""
    drop = {f.name: getattr(scenario, f.name) for f in dc.fields(scenario) if f.name not in AFTER_THE_DROP}
    text = "\n".join([repr(robot), repr(drop), *(repr(m) for m in objects), f"seed={seed}"])
    return hashlib.sha256(text.encode()).hexdigest()[:32]


class SettledScenes:
    """Settled states in a folder, one `.npz` file a scene; safe for worker processes sharing the folder."""

    def __init__(self, folder: str | os.PathLike):
        self.folder = Path(folder)

    def load(self, key: str) -> SettledState | None:
        """The state kept under `key`, or None."""
        path = self.folder / f"{key}.npz"
        if not path.exists():
            return None
        with np.load(path) as data:
            count = int(data["groups"])
            return SettledState(float(data["time"]), tuple(data[f"group{i}"] for i in range(count)))

    def save(self, key: str, state: SettledState) -> None:
        """Keeps `state` under `key` (written whole, then renamed: a reader never sees half a file)."""
        self.folder.mkdir(parents=True, exist_ok=True)
        partial = self.folder / f"{key}.{os.getpid()}.partial.npz"
        np.savez(partial, time=state.time, groups=len(state.discrete),
                 **{f"group{i}": values for i, values in enumerate(state.discrete)})
        os.replace(partial, self.folder / f"{key}.npz")
