"""Failure memory: grasps that failed are not tried again while the scene stays the same.

After a failed attempt, an unchanged scene gives the same ranking, so the policy
would propose the same grasp again. The memory keeps each failed grasp (its point
and approach direction). A candidate "near" a remembered grasp (point within
`radius`, approach within `angle_deg`) is excluded:
- a grasp that failed to plan, for the rest of the run (the plan's reachability does
  not depend on the objects);
- a grasp that failed in execution, or whose transit was blocked by the objects, as
  long as the scene has not changed: once something moved `scene_change` or more since
  that attempt began (as the cell's judge sees the scene: `cell.judges.Scene`), those
  grasps may be tried again.
The memory always records, so that repeats are counted even when it excludes nothing.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from drake_grasp.cell.judges import Scene


@dataclass(frozen=True)
class MemoryConfig:
    radius: float = 0.02  # grasp points this close are the same grasp [m]
    angle_deg: float = 20.0  # approach directions this close are the same grasp
    scene_change: float = 0.01  # something that moved this much changed the scene [m]


def _point_and_axis(X_WG: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    X_WG = np.asarray(X_WG, dtype=float).reshape(-1, 4, 4)
    return X_WG[:, :3, 3], X_WG[:, :3, 2]


@dataclass
class FailureMemory:
    config: MemoryConfig = field(default_factory=MemoryConfig)
    unplannable: list[np.ndarray] = field(default_factory=list)  # X_WG of grasps that did not plan
    failed: list[np.ndarray] = field(default_factory=list)  # X_WG of grasps that failed in this scene
    scene: Scene | None = None  # the scene when the last remembered failure began

    def copy(self) -> FailureMemory:
        """A copy whose lists grow apart from this one's (the remembered poses are shared: never mutated)."""
        return FailureMemory(self.config, list(self.unplannable), list(self.failed), self.scene)

    def observe(self, scene: Scene) -> None:
        """Forgets the scene-dependent failures once the scene changed by `scene_change` or more."""
        if self.scene is None or not self.failed:
            return
        if scene.changed_since(self.scene, self.config.scene_change):
            self.failed.clear()
            self.scene = None

    def remember(self, X_WG: np.ndarray, *, scene_dependent: bool, scene: Scene) -> None:
        """Records a failed grasp; `scene` as it was when its attempt began."""
        if scene_dependent:
            self.failed.append(np.asarray(X_WG, dtype=float))
            self.scene = scene
        else:
            self.unplannable.append(np.asarray(X_WG, dtype=float))

    def excluded(self, X_WG: np.ndarray) -> np.ndarray:
        """(N,) bool: which candidates are near a remembered failure."""
        points, axes = _point_and_axis(X_WG)
        out = np.zeros(len(points), dtype=bool)
        remembered = self.unplannable + self.failed
        if not remembered:
            return out
        cos_limit = np.cos(np.radians(self.config.angle_deg))
        for X in remembered:
            (p,), (z,) = _point_and_axis(X)
            out |= (np.linalg.norm(points - p, axis=1) <= self.config.radius) & (axes @ z >= cos_limit)
        return out


def successive_choices(X_WG: np.ndarray, order: np.ndarray, count: int,
                       config: MemoryConfig | None = None) -> np.ndarray:
    """Indices of the first `count` candidates a policy would try in an unchanged scene if each failed:
    in its `order` (indices, best first: `policy.selector.ranked_order`), each skipping the candidates
    near those before it (`FailureMemory.excluded`)."""
    memory = FailureMemory(config or MemoryConfig())
    chosen: list[int] = []
    for i in order:
        if len(chosen) == count:
            break
        if not memory.excluded(X_WG[i:i + 1])[0]:
            chosen.append(int(i))
            memory.failed.append(np.asarray(X_WG[i], dtype=float))
    return np.array(chosen, dtype=int)
