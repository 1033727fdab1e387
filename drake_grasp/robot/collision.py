"""The robot's collision model: the arm and open hand against a fixed world (the table, observed columns).

Built on the one plant assembly (`robot.plant`), so planning and the arm loader's home check
see the very geometry the physics does; Drake's `SceneGraphCollisionChecker` answers. The
observed objects' columns are shapes added to the checker and removed again (`set_columns`), so
one model serves every attempt.
"""

from __future__ import annotations

import numpy as np
from pydrake.common import Parallelism
from pydrake.geometry import Box, ProximityProperties
from pydrake.math import RigidTransform
from pydrake.planning import RobotDiagramBuilder, SceneGraphCollisionChecker

from drake_grasp.robot.paths import add_package
from drake_grasp.robot.plant import add_scene, filter_hand_collisions, hand_open_positions
from drake_grasp.robot.specs import RobotSpec

OBSERVED_GROUP = "observed_columns"
MIN_COLUMN_HEIGHT = 0.005  # a column of points on the table top still blocks [m]
MAX_ADDED_COLUMNS = 60  # more new columns than this: a new checker is faster than adding them


class CollisionModel:
    """Drake collision checking of the arm + open hand against a fixed world (table, observed objects)."""

    def __init__(self, robot: RobotSpec, *, table_height: float):
        self.robot, self.table_height = robot, table_height
        self._build(frozenset())

    def _build(self, columns: frozenset) -> None:
        """A new checker of the robot, the table and `columns` ((x, y, bottom, top, cell) keys) as fixed
        geometry."""
        builder = RobotDiagramBuilder(time_step=0.0)
        add_package(builder.parser().package_map())
        plant = builder.plant()
        models = add_scene(plant, builder.parser(), robot=self.robot, table_height=self.table_height)
        for k, key in enumerate(sorted(columns)):
            X_WB, box = self._column(*key)
            plant.RegisterCollisionGeometry(plant.world_body(), X_WB, box, f"observed_column_{k}",
                                            ProximityProperties())
        plant.Finalize()
        filter_hand_collisions(plant, builder.scene_graph(), models)
        self.arm, self.hand = models.arm, models.hand
        self.checker = SceneGraphCollisionChecker(
            model=builder.Build(), robot_model_instances=[self.arm, self.hand],
            edge_step_size=0.05, env_collision_padding=0.002, self_collision_padding=0.002,
            implicit_context_parallelism=Parallelism(1),
        )
        self._built_with = columns  # fixed in this checker: another set of columns needs a new one
        self._column_groups: dict[tuple[float, ...], str] = {}  # (x, y, bottom, top, cell) -> group
        self._next_group = 0
        self.plant = self.checker.plant()
        self.plant_context = self.checker.MakeStandaloneModelContext().plant_context()
        self.arm_slice = self._positions_slice(self.arm)
        self.hand_slice = self._positions_slice(self.hand)
        self.hand_open = hand_open_positions(self.plant, models)  # the hand's positions, open
        self._q_full = self.plant.GetPositions(self.plant_context).copy()
        self._q_full[self.hand_slice] = self.hand_open

    def _column(self, x: float, y: float, bottom: float, top: float, cell: float,
                ) -> tuple[RigidTransform, Box]:
        bottom = max(bottom, self.table_height)
        height = max(top - bottom, MIN_COLUMN_HEIGHT)
        return RigidTransform([x, y, bottom + height / 2]), Box(cell, cell, height)

    def set_columns(self, columns: np.ndarray, cell: float) -> None:
        """The fixed world's observed columns (M, 4): a `cell`-wide box at each (x, y) from its bottom (at
        least the table top; -inf: the table) up to its top; replaces the columns set before.

        A few changed columns are added to the checker and removed from it, each its own shape group,
        so the columns that stay (the next attempt's cloud mostly repeats the last) are kept; adding a
        shape costs milliseconds, more the more the checker holds, so many new columns (a noisy
        camera's) get a new checker with them as fixed geometry instead.
        """
        wanted = _column_keys(columns, cell)
        if wanted == self._built_with | set(self._column_groups):
            return
        if self._built_with or len(wanted - set(self._column_groups)) > MAX_ADDED_COLUMNS:
            self._build(wanted if len(wanted) > MAX_ADDED_COLUMNS else frozenset())
            if self._built_with:
                return
        for key in set(self._column_groups) - wanted:
            self.checker.RemoveAllAddedCollisionShapes(self._column_groups.pop(key))
        world = self.plant.world_body()
        for key in sorted(wanted - set(self._column_groups)):
            X_WB, box = self._column(*key)
            group = f"{OBSERVED_GROUP}_{self._next_group}"
            self._next_group += 1
            self.checker.AddCollisionShapeToBody(group, world, box, X_WB)
            self._column_groups[key] = group

    def set_fixed_columns(self, columns: np.ndarray, cell: float) -> None:
        """As `set_columns`, but always as the fixed geometry of a new checker (unless they are the same):
        then they are in the plant's scene graph too, for an IK that keeps the arm off them."""
        wanted = _column_keys(columns, cell)
        if wanted != self._built_with or self._column_groups:
            self._build(wanted)

    @property
    def num_columns(self) -> int:
        return len(self._built_with) + len(self._column_groups)

    def _positions_slice(self, instance) -> slice:
        """Where a model instance's positions lie in the plant's (they are contiguous)."""
        joints = [self.plant.get_joint(i) for i in self.plant.GetJointIndices(instance)]
        start = min(j.position_start() for j in joints if j.num_positions() > 0)
        return slice(start, start + self.plant.num_positions(instance))

    def full(self, q_arm: np.ndarray) -> np.ndarray:
        """The plant's positions: the arm at q_arm, the hand open."""
        q = self._q_full.copy()
        q[self.arm_slice] = q_arm
        return q

    def is_free(self, q_arm: np.ndarray) -> bool:
        try:
            return bool(self.checker.CheckConfigCollisionFree(self.full(q_arm)))
        except RuntimeError:
            return False  # FCL's GJK gave up on a near-degenerate capsule pair: count it as a collision

    def is_edge_free(self, q1: np.ndarray, q2: np.ndarray) -> bool:
        try:
            return bool(self.checker.CheckEdgeCollisionFree(self.full(q1), self.full(q2)))
        except RuntimeError:
            return False

    def is_path_free(self, path: list[np.ndarray]) -> bool:
        return all(self.is_edge_free(a, b) for a, b in zip(path, path[1:], strict=False))


def _column_keys(columns: np.ndarray, cell: float) -> frozenset:
    """(x, y, bottom, top, cell) keys of (M, 4) columns: what a checker holds them by."""
    return frozenset((float(x), float(y), float(bottom), float(top), float(cell))
                     for x, y, bottom, top in np.asarray(columns, dtype=float).reshape(-1, 4))
