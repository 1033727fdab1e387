"""The robot's collision model: the arm and open hand against a fixed world (the table, observed columns).

Built on the one plant assembly (`robot.plant`), so planning and the arm loader's home check
see the very geometry the physics does; Drake's `SceneGraphCollisionChecker` answers. The
observed objects' columns are shapes added to the checker (`set_columns`), so one model serves
every attempt and is never rebuilt.
"""

from __future__ import annotations

import numpy as np
from pydrake.common import Parallelism
from pydrake.geometry import Box
from pydrake.math import RigidTransform
from pydrake.planning import RobotDiagramBuilder, SceneGraphCollisionChecker

from drake_grasp.robot.hand import HAND_OPEN
from drake_grasp.robot.paths import add_package
from drake_grasp.robot.plant import add_scene, filter_hand_collisions
from drake_grasp.robot.specs import RobotSpec

OBSERVED_GROUP = "observed_columns"
MIN_COLUMN_HEIGHT = 0.005  # a column of points on the table top still blocks [m]


class CollisionModel:
    """Drake collision checking of the arm + open hand against a fixed world (table, observed objects)."""

    def __init__(self, robot: RobotSpec, *, table_height: float):
        builder = RobotDiagramBuilder(time_step=0.0)
        add_package(builder.parser().package_map())
        plant = builder.plant()
        models = add_scene(plant, builder.parser(), robot=robot, table_height=table_height)
        plant.Finalize()
        filter_hand_collisions(plant, builder.scene_graph(), models)
        self.arm, self.hand = models.arm, models.hand
        self.checker = SceneGraphCollisionChecker(
            model=builder.Build(), robot_model_instances=[self.arm, self.hand],
            edge_step_size=0.05, env_collision_padding=0.002, self_collision_padding=0.002,
            implicit_context_parallelism=Parallelism(1),
        )
        self.table_height = table_height
        self._column_groups: dict[tuple[float, float, float, float], str] = {}  # (x, y, top, cell) -> group
        self._next_group = 0
        self.plant = self.checker.plant()
        self.plant_context = self.checker.MakeStandaloneModelContext().plant_context()
        self.arm_slice = self._positions_slice(self.arm, robot.joint_names[0])
        self.hand_slice = self._positions_slice(self.hand, "left_finger_joint")
        self._q_full = self.plant.GetPositions(self.plant_context).copy()
        self._q_full[self.hand_slice] = HAND_OPEN

    def set_columns(self, columns: np.ndarray, cell: float) -> None:
        """The fixed world's observed columns (M, 3): a `cell`-wide box at each (x, y) from the table
        top up to z; replaces the columns set before.

        Each column is its own shape group, so a column that stays (the next attempt's cloud mostly
        repeats the last) is kept and only the changed ones are removed and added: adding a shape
        costs milliseconds, more the more shapes the checker holds.
        """
        wanted = {(float(x), float(y), float(top), float(cell))
                  for x, y, top in np.asarray(columns, dtype=float).reshape(-1, 3)}
        for key in set(self._column_groups) - wanted:
            self.checker.RemoveAllAddedCollisionShapes(self._column_groups.pop(key))
        world = self.plant.world_body()
        for key in sorted(wanted - set(self._column_groups)):
            x, y, top, size = key
            height = max(top - self.table_height, MIN_COLUMN_HEIGHT)
            group = f"{OBSERVED_GROUP}_{self._next_group}"
            self._next_group += 1
            self.checker.AddCollisionShapeToBody(group, world, Box(size, size, height),
                                                 RigidTransform([x, y, self.table_height + height / 2]))
            self._column_groups[key] = group

    @property
    def num_columns(self) -> int:
        return len(self._column_groups)

    def _positions_slice(self, instance, first_joint: str) -> slice:
        start = self.plant.GetJointByName(first_joint, instance).position_start()
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
