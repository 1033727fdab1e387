"""Self-supervised grasp trials in physics: a floating hand grasps an object on the table, alone or in a pile.

The trial scene is the closed loop's station with the hand on a floating mount
instead of an arm (`Station(robot=None)`): the same plant assembly, table, hand,
contact model, gains, depth camera and perception.

One trial of a grasp X_WG (paper Sec. IV-D), from the settled scene each time:
1. approach: the open hand must get from the pre-grasp (`PREGRASP_DISTANCE` back
   along the approach axis) to the grasp without touching the object or the table,
   checked on Drake's collision geometry every centimetre ("hand collides on
   approach": no physics needed, the rigidly held hand would have pushed the object
   or stopped at the table);
2. close the fingers, lift the hand `LIFT_TRAVEL` and hold it, in physics, with the
   task's timings (`drake_grasp.robot.task`);
3. judge with the task's own rule (`robot.task.judge_grasp`): label 1 when the object ends
   at least `LIFT_HEIGHT` higher and between the fingers (touching both), else
   "closed on nothing", "not in the hand", "object slipped" or "not lifted". Jaws that
   meet during the close end the trial there, "closed on nothing", as the closed loop
   senses it and lets go (the lift is not simulated).
In a pile the judged object is the one between the fingers, else the one that rose most.
A trial whose simulation diverges is a failure, "simulation diverged"; the next trial starts
again from the settled scene.

With the scenario's object sleep on (the `pile` scenario has it), objects resting away
from the grasp are locked through the trial (`drake_grasp.simulation.sleep`, polled every
`POLL_S`, waking as soon as the hand or a moving object comes near): a pile trial then
solves contact only around the grasp.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Role
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Context, DiagramBuilder
from pydrake.systems.primitives import TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from drake_grasp.perception.cloud import ObjectCloud, extract_object_cloud
from drake_grasp.robot.hand import HandSpec
from drake_grasp.robot.plant import mount_positions, set_hand_joints
from drake_grasp.robot.task import (
    CLOSE_DURATION,
    EMPTY_CLOSE_CHECK,
    HOLD_DURATION,
    LIFT_DURATION,
    LIFT_TRAVEL,
    PREGRASP_DISTANCE,
    TrialOutcome,
    judge_grasp,
)
from drake_grasp.simulation.contacts import between_fingers
from drake_grasp.simulation.divergence import is_divergence
from drake_grasp.simulation.lifetime import release_python_systems
from drake_grasp.simulation.objects import ObjectModel
from drake_grasp.simulation.placement import place_objects
from drake_grasp.simulation.scenario import Scenario
from drake_grasp.simulation.sleep import ObjectSleep
from drake_grasp.simulation.station import Station

APPROACH_CHECKS = 11  # hand poses checked from the pre-grasp to the grasp: every 1 cm
X_W_PARK = RigidTransform([-1.0, 0.0, 1.0])  # the hand waits out of the camera's view
POLL_S = 0.1  # [s] between object-sleep updates in a trial


@dataclass
class TrialResult:
    outcome: TrialOutcome
    rise: float  # how much higher the judged object ended [m]
    object_index: int = 0  # the judged object (in a pile: the one in the hand, else the one that rose most)

    @property
    def success(self) -> bool:
        return self.outcome is TrialOutcome.SUCCESS


class GraspTrialScene:
    """Objects on the table (one, or a pile: the scenario's clusters), a depth camera and the floating
    hand, ready for many trials.

    With `meshcat`, the scene is drawn there; `visualizer.StartRecording()` before a
    trial and `PublishRecording()` after it make the trial replayable.
    """

    def __init__(self, scenario: Scenario, model: ObjectModel | Sequence[ObjectModel],
                 meshcat: Meshcat | None = None, noise_seed: int = 0, hand: HandSpec | None = None):
        models = [model] if isinstance(model, ObjectModel) else list(model)
        if len(models) != scenario.num_objects:
            raise ValueError(f"scenario '{scenario.name}' places {scenario.num_objects} objects, "
                             f"got {len(models)}")
        self.scenario = scenario
        builder = DiagramBuilder()
        self.station = builder.AddSystem(Station(scenario=scenario, robot=None, objects=models,
                                                 noise_seed=noise_seed, hand=hand))
        self.plant = self.station.plant()
        self.hand, self.mount = self.station.models.hand, self.station.models.mount
        self.hand_spec = self.station.models.hand_spec
        self._driven_joint = self.plant.GetJointByName(self.hand_spec.driven_joint, self.hand)
        parked = PiecewisePolynomial(mount_positions(X_W_PARK).reshape(-1, 1))
        self._mount_source = builder.AddNamedSystem("mount_command", TrajectorySource(parked, 1))
        builder.Connect(self._mount_source.get_output_port(),
                        self.station.GetInputPort("mount_desired_state"))
        self.visualizer = None if meshcat is None else MeshcatVisualizer.AddToBuilder(
            builder, self.station.GetOutputPort("query_object"), meshcat,
            MeshcatVisualizerParams(role=Role.kIllustration))
        self.diagram = builder.Build()
        self.simulator = Simulator(self.diagram)
        self.context = self.simulator.get_mutable_context()
        self.plant_context = self.station.plant_context(self.context)
        self._station_context = self.station.GetMyMutableContextFromRoot(self.context)
        self._hand_geometries = {g for i in self.plant.GetBodyIndices(self.hand)
                                 for g in self.plant.GetCollisionGeometriesForBody(self.plant.get_body(i))}
        self.sleep = ObjectSleep(self.plant, self.station.scene_graph(), self.station.object_bodies,
                                 self.station.robot_bodies, scenario.object_sleep)
        self._settled: Context | None = None
        self._z_settled = np.zeros(len(models))

    def release(self) -> None:
        """Frees the scene's diagram once its trials are done (`simulation.lifetime`); no trial runs
        afterwards."""
        release_python_systems(self.diagram)

    # -- the scene ------------------------------------------------------------------------
    def _set_hand(self, X_WH: RigidTransform, finger: float) -> None:
        plant, context = self.plant, self.plant_context
        plant.SetPositions(context, self.mount, mount_positions(X_WH))
        plant.SetVelocities(context, self.mount, np.zeros(6))
        set_hand_joints(plant, context, self.station.models, finger)
        plant.SetVelocities(context, self.hand, np.zeros(plant.num_velocities(self.hand)))

    def settle(self, rng: np.random.Generator) -> None:
        """Drops the object at a random pose (the scenario's cluster) and lets it come to rest."""
        self.context.SetTime(0.0)
        place_objects(self.plant, self.plant_context, self.station.scene_graph().model_inspector(),
                      self.station.object_bodies, self.scenario, rng)
        self._set_hand(X_W_PARK, self.hand_spec.open_position)
        self._command(PiecewisePolynomial(mount_positions(X_W_PARK).reshape(-1, 1)),
                      self.hand_spec.open_position)
        self.simulator.Initialize()
        self.simulator.AdvanceTo(self.scenario.settle_time)
        self._settled = copy.deepcopy(self.context)
        self._z_settled = self.object_heights()

    def object_pose(self, k: int = 0) -> RigidTransform:
        return self.plant.EvalBodyPoseInWorld(self.plant_context, self.station.object_bodies[k])

    def object_heights(self) -> np.ndarray:
        return np.array([self.object_pose(k).translation()[2] for k in range(self.scenario.num_objects)])

    def observe(self) -> ObjectCloud:
        """The object cloud as the closed loop sees it: depth image -> crop -> RANSAC."""
        points = self.station.GetOutputPort("point_cloud_W").Eval(self._station_context).xyzs().T
        workspace = self.scenario.sensing.workspace
        return extract_object_cloud(points, lower=workspace.lower, upper=workspace.upper)

    def _command(self, mount: PiecewisePolynomial, finger: float) -> None:
        self._mount_source.UpdateTrajectory(mount)
        self.station.GetInputPort("hand_desired_state").FixValue(self._station_context, [finger, 0.0])

    # -- one trial ------------------------------------------------------------------------
    def _reset(self) -> None:
        if self._settled is None:
            raise RuntimeError("settle() the scene before running trials")
        self.context.SetTimeStateAndParametersFrom(self._settled)  # (locks and collision filters too)
        self.sleep.forget()

    def hand_touches_something(self) -> bool:
        query = self.station.GetOutputPort("query_object").Eval(self._station_context)
        return any(p.id_A in self._hand_geometries or p.id_B in self._hand_geometries
                   for p in query.ComputePointPairPenetration())

    def approach_collides(self, X_WG: RigidTransform) -> bool:
        """Whether the open hand touches anything on its way from the pre-grasp to the grasp."""
        self._reset()
        X_WH = X_WG @ self.hand_spec.X_GH
        for s in np.linspace(1.0, 0.0, APPROACH_CHECKS):
            self._set_hand(X_WH @ RigidTransform([0.0, 0.0, -s * PREGRASP_DISTANCE]),
                           self.hand_spec.open_position)
            if self.hand_touches_something():
                return True
        return False

    def run(self, X_WG: np.ndarray | RigidTransform) -> TrialResult:
        """Approach check, then close, lift and hold in physics; the task's success rule."""
        X_WG = X_WG if isinstance(X_WG, RigidTransform) else RigidTransform(np.asarray(X_WG))
        if self.approach_collides(X_WG):
            return TrialResult(TrialOutcome.COLLIDES_ON_APPROACH, 0.0)
        self._reset()
        X_WH = X_WG @ self.hand_spec.X_GH
        self._set_hand(X_WH, self.hand_spec.open_position)
        q_grasp = mount_positions(X_WH)
        q_lift = q_grasp + [0.0, 0.0, LIFT_TRAVEL, 0.0, 0.0, 0.0]
        t0 = self.context.get_time()
        times = t0 + np.cumsum([0.0, CLOSE_DURATION, LIFT_DURATION, HOLD_DURATION])
        knots = np.column_stack([q_grasp, q_grasp, q_lift, q_lift])
        self._command(PiecewisePolynomial.CubicHermite(times, knots, np.zeros_like(knots)),
                      self.hand_spec.closed_position)
        try:
            self.simulator.Initialize()
            jaws_met = self._advance(times[-1], X_WG.translation(), watch_close=(t0, times[1]))
        except RuntimeError as e:
            if not is_divergence(e):
                raise
            return TrialResult(TrialOutcome.DIVERGED, 0.0)
        rises = self.object_heights() - self._z_settled
        if jaws_met:  # sensed as the cell senses it: the grasp ends here
            k = int(np.argmax(rises))
            return TrialResult(TrialOutcome.CLOSED_ON_NOTHING, float(rises[k]), k)
        held = [k for k in range(len(rises)) if self.in_hand(k)]
        k = held[0] if held else int(np.argmax(rises))
        judgement = judge_grasp(float(rises[k]), self.hand_spec.jaws_met(self._finger()), bool(held),
                                self.scenario.success_rule)
        outcome = TrialOutcome.from_judgement(judgement)
        return TrialResult(outcome, float(rises[k]), k)

    def _finger(self) -> float:
        """The driven joint's position."""
        return float(self._driven_joint.GetOnePosition(self.plant_context))

    def _advance(self, t_end: float, p_WGrasp: np.ndarray,
                 watch_close: tuple[float, float] | None = None) -> bool:
        """Simulates to `t_end`; with object sleep on, in `POLL_S` steps, the fingers and the grasp point
        as the focus.

        With `watch_close` = (start, end) of the close, it steps by `POLL_S` through the close
        and stops early, returning True, when the jaws met (`EMPTY_CLOSE_CHECK` or more into
        it): the closed loop senses that at once and lets go, so the lift is never simulated.
        """
        while True:
            t = self.context.get_time()
            if self.sleep.config.enabled:
                contacts = self.station.GetOutputPort("body_contacts").Eval(self._station_context)
                focus = np.vstack([self.station.finger_positions(self.context), p_WGrasp])
                self.sleep.update(self.context, focus, contacts)
            if t >= t_end - 1e-9:
                return False
            watching = watch_close is not None and t <= watch_close[1] + 1e-9
            sensing = watching and t >= watch_close[0] + EMPTY_CLOSE_CHECK - 1e-9
            if sensing and self.hand_spec.jaws_met(self._finger()):
                return True
            if not watching and not self.sleep.config.enabled:
                self.simulator.AdvanceTo(t_end)
            else:
                self.simulator.AdvanceTo(min(t_end, t + POLL_S))

    def in_hand(self, k: int = 0) -> bool:
        """Whether object k touches both fingers."""
        pairs = self.station.GetOutputPort("body_contacts").Eval(self._station_context)
        return between_fingers(pairs, int(self.station.object_bodies[k].index()), self.station.finger_bodies)
