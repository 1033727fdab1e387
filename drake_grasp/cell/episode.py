"""One closed-loop grasping run (an episode) and its metrics.

The cell (`drake_grasp.cell.diagram`) is built for a seeded scene; the driver
advances its simulator attempt by attempt; `EpisodeLedger` (pure bookkeeping, no physics)
records each attempt, says which objects leave the scene (grasped: taken from the
hand at home, as into a bin; or fallen off the table) and when the run ends: no
object left, `max_consecutive_failures` failures in a row (planning failures
included unless the scenario counts them apart, `max_consecutive_plan_failures`; a push that
moved nothing is a failure too), `max_attempts` (grasps and
pushes), or the executive found nothing worth trying (nothing
reachable, nothing graspable, or every candidate failed before).

A simulation that diverges (at a coarse step, a thin or light object that a stiff contact
sets spinning can blow up) starts the run over once, from the same seed, at half the
physics step; the first try is kept in `EpisodeResult.diverged_try`. A run that
diverges again ends there (`DIVERGED`): the attempt in flight counts as a failed attempt
of that name and every attempt before it is kept.
"""

from __future__ import annotations

import dataclasses as dc
import functools
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
from pydrake.geometry import Meshcat

from drake_grasp.cell.diagram import GraspCell, build_cell, run_attempt
from drake_grasp.cell.executive import END_MODES, Attempt, CellConfig, ExecutiveState, Mode
from drake_grasp.policy.scorers import Scorer
from drake_grasp.robot.specs import RobotSpec
from drake_grasp.robot.stages import stage
from drake_grasp.simulation.divergence import DIVERGED, first_line, is_divergence
from drake_grasp.simulation.objects import ObjectModel
from drake_grasp.simulation.placement import FELL_OFF_Z, park_object
from drake_grasp.simulation.scenario import Scenario
from drake_grasp.simulation.settled import SettledScenes

RESETTLE_S = 0.3  # physics after the arm returns home, before the next image [s]
NO_OBJECTS_IN_VIEW = Mode.NO_OBJECTS.value
NOTHING_REACHABLE = Mode.NOTHING_REACHABLE.value
ALL_REMOVED = "all objects removed"
EXECUTING = (Mode.TRANSIT, Mode.APPROACH, Mode.CLOSE, Mode.LIFT, Mode.HOLD, Mode.RELEASE, Mode.RETREAT,
             Mode.PUSH, Mode.RETURN)  # the modes of an attempt under way (planned, not yet recorded)


@dataclass
class EpisodeResult:
    seed: int
    num_objects: int
    attempts: int = 0
    successes: int = 0
    plans_tried: int = 0
    plans_succeeded: int = 0
    objects_grasped: int = 0
    objects_fell_off: int = 0
    repeated_failures: int = 0  # failed attempts near a grasp that already failed on the unchanged scene
    transit_contacts: int = 0  # objects the robot touched in transit, summed over attempts
    unplanned_returns: int = 0  # returns home that found no collision-free path
    end_reason: str = ""
    divergence: str = ""  # Drake's message when the simulation diverged (end_reason DIVERGED)
    attempts_saved: int = 0  # by an early end: attempts the run had left before its other limits
    pushes: int = 0  # push actions (VPG with pushing), not counted in `attempts`
    pushes_planned: int = 0
    pushes_moved: int = 0  # pushes that moved an object
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    failures: dict[str, int] = field(default_factory=dict)
    attempt_log: list[dict] = field(default_factory=list)
    objects_left: list[dict] = field(default_factory=list)  # at the end: each object's name and p_WO [m]
    # The try at the scenario's step, when it diverged and the run was started over at half the step:
    # its time_step [s], divergence, attempts, sim_time_s and wall_time_s (the run's wall time includes it).
    diverged_try: dict | None = None

    @property
    def grasp_success_rate(self) -> float:
        return self.successes / self.attempts if self.attempts else 0.0

    @property
    def completion_rate(self) -> float:
        return self.objects_grasped / self.num_objects if self.num_objects else 0.0

    @property
    def planning_success_rate(self) -> float:
        return self.plans_succeeded / self.plans_tried if self.plans_tried else 0.0

    @property
    def wasted_attempts(self) -> int:
        """Failed plans plus repeated failures (a repeat that also failed to plan counts once)."""
        repeats = sum(1 for a in self.attempt_log if a["repeat"] and a["planned"] and not a["success"])
        return (self.plans_tried - self.plans_succeeded) + repeats

    def to_dict(self) -> dict:
        out = asdict(self)
        out.update(grasp_success_rate=self.grasp_success_rate, completion_rate=self.completion_rate,
                   planning_success_rate=self.planning_success_rate, wasted_attempts=self.wasted_attempts)
        return out


class EpisodeLedger:
    """The run's bookkeeping: counts, the objects still in the scene, and when the run ends."""

    def __init__(self, *, seed: int, object_names: Sequence[str], max_consecutive_failures: int,
                 max_attempts: int = 0, max_consecutive_plan_failures: int = 0):
        self.result = EpisodeResult(seed=seed, num_objects=len(object_names))
        self.object_names = list(object_names)
        self.present = np.ones(len(object_names), dtype=bool)
        self.max_consecutive_failures = max_consecutive_failures
        self.max_attempts = max_attempts
        self.max_consecutive_plan_failures = max_consecutive_plan_failures  # 0: failed plans are failures
        self.consecutive_failures = 0
        self.consecutive_plan_failures = 0

    @stage("bookkeeping")
    def record(self, attempt: Attempt, t: float) -> dict:
        """Counts one finished attempt (a grasped object leaves the scene); returns its log entry."""
        r = self.result
        if attempt.push:
            return self._record_push(attempt, t)
        r.attempts += 1
        r.plans_tried += 1
        r.plans_succeeded += attempt.planned
        self.consecutive_plan_failures = 0 if attempt.planned else self.consecutive_plan_failures + 1
        if attempt.success:
            r.successes += 1
            r.objects_grasped += 1
            self.present[attempt.object_index] = False
            self.consecutive_failures = 0
        else:
            r.failures[attempt.failure] = r.failures.get(attempt.failure, 0) + 1
            r.repeated_failures += attempt.repeat
            if attempt.planned or not self.max_consecutive_plan_failures:
                self.consecutive_failures += 1
        r.transit_contacts += attempt.transit_contacts
        r.unplanned_returns += attempt.planned and not attempt.return_planned
        return self._log(attempt, t)

    def _record_push(self, attempt: Attempt, t: float) -> dict:
        r = self.result
        r.pushes += 1
        r.pushes_planned += attempt.planned
        r.pushes_moved += attempt.success
        self.consecutive_failures += not attempt.success
        r.transit_contacts += attempt.transit_contacts
        r.unplanned_returns += attempt.planned and not attempt.return_planned
        return self._log(attempt, t)

    def _log(self, attempt: Attempt, t: float) -> dict:
        """The attempt's log entry (`push` only on pushes), appended to the result."""
        entry = asdict(attempt) | {"t": round(t, 3)}
        if not attempt.push:
            del entry["push"]
        if attempt.object_index is not None:
            entry["object"] = self.object_names[attempt.object_index]
        self.result.attempt_log.append(entry)
        return entry

    @property
    def actions(self) -> int:
        """Grasp attempts and pushes."""
        return self.result.attempts + self.result.pushes

    def remove_fallen(self, heights: np.ndarray) -> None:
        """Objects below FELL_OFF_Z have left the table: they leave the scene and are counted."""
        fallen = self.present & (np.asarray(heights) < FELL_OFF_Z)
        self.present &= ~fallen
        self.result.objects_fell_off += int(fallen.sum())

    def end_early(self, reason: str) -> None:
        """The executive ended the run; the attempts it saved are those the other limits still allowed."""
        left = self.max_consecutive_failures - self.consecutive_failures
        if self.max_attempts:
            left = min(left, self.max_attempts - self.actions)
        self.result.end_reason, self.result.attempts_saved = reason, max(0, left)

    def end_reason(self) -> str | None:
        """Why the run ends after the attempts recorded so far, or None to go on."""
        if not self.present.any():
            return ALL_REMOVED
        if self.consecutive_failures >= self.max_consecutive_failures:
            return f"{self.consecutive_failures} consecutive failures"
        if self.max_consecutive_plan_failures and \
                self.consecutive_plan_failures >= self.max_consecutive_plan_failures:
            return f"{self.consecutive_plan_failures} failed plans in a row"
        if self.max_attempts and self.actions >= self.max_attempts:
            pushes = f" and {self.result.pushes} pushes" if self.result.pushes else ""
            return f"{self.result.attempts} attempts{pushes} (the scenario's limit)"
        return None


@stage("physics")
def run_episode(*, robot: RobotSpec, scenario: Scenario, scorer: Scorer, object_models: list[ObjectModel],
                seed: int, cell: CellConfig | None = None, meshcat: Meshcat | None = None,
                on_attempt: Callable[[int, dict], None] | None = None,
                on_restart: Callable[[], None] | None = None,
                settled: SettledScenes | None = None) -> EpisodeResult:
    """Builds the cell for one seeded scene and grasps until the run ends; a run that diverges is
    started over once at half the physics step (`on_attempt` hears the attempts of both tries,
    `on_restart` when the second begins). With `settled`, the dropped scene is shared with other runs
    of the same scene (`build_cell`)."""
    run_once = functools.partial(_run_once, robot=robot, scorer=scorer, object_models=object_models,
                                 seed=seed, cell=cell, meshcat=meshcat, on_attempt=on_attempt,
                                 settled=settled)
    result = run_once(scenario)
    if result.end_reason != DIVERGED:
        return result
    step = scenario.plant_config.time_step
    if on_restart is not None:
        on_restart()
    rerun = run_once(scenario.with_time_step(step / 2))
    rerun.diverged_try = {"time_step": step, "divergence": result.divergence, "attempts": result.attempts,
                          "sim_time_s": result.sim_time_s, "wall_time_s": result.wall_time_s}
    rerun.wall_time_s += result.wall_time_s
    return rerun


def _run_once(scenario: Scenario, *, robot: RobotSpec, scorer: Scorer, object_models: list[ObjectModel],
              seed: int, cell: CellConfig | None, meshcat: Meshcat | None,
              on_attempt: Callable[[int, dict], None] | None, settled: SettledScenes | None) -> EpisodeResult:
    """One try of `run_episode` at the scenario's step."""
    wall_start = time.perf_counter()
    try:
        grasp_cell = build_cell(robot=robot, scenario=scenario, scorer=scorer, object_models=object_models,
                                seed=seed, cell=cell, meshcat=meshcat, settled=settled)
    except RuntimeError as e:
        if not is_divergence(e):
            raise
        result = EpisodeResult(seed=seed, num_objects=scenario.num_objects, end_reason=DIVERGED,
                               divergence=f"while the objects settled: {first_line(e)}")
        result.wall_time_s = time.perf_counter() - wall_start
        return result
    try:
        result = _grasp_and_account(grasp_cell, scenario, seed, on_attempt)
    finally:
        grasp_cell.release()  # (pydrake would keep the cell's diagram for good: `simulation.lifetime`)
    result.wall_time_s = time.perf_counter() - wall_start
    return result


def _grasp_and_account(grasp_cell: GraspCell, scenario: Scenario, seed: int,
                       on_attempt: Callable[[int, dict], None] | None) -> EpisodeResult:
    """Grasps in a built cell until the run ends; the run's result, with the objects left and the
    simulated time (not its wall time)."""
    ledger = EpisodeLedger(seed=seed, object_names=[m.name for m in grasp_cell.objects],
                           max_consecutive_failures=scenario.max_consecutive_failures,
                           max_attempts=scenario.max_attempts,
                           max_consecutive_plan_failures=scenario.max_consecutive_plan_failures)
    try:
        _grasp_until_done(grasp_cell, ledger, on_attempt)
    except RuntimeError as e:
        if not is_divergence(e):
            raise
        in_flight = _attempt_in_flight(grasp_cell.task_state())
        if in_flight is not None:
            entry = ledger.record(in_flight, grasp_cell.context.get_time())
            if on_attempt is not None:
                on_attempt(ledger.actions, entry)
        ledger.result.end_reason, ledger.result.divergence = DIVERGED, first_line(e)
    station, context = grasp_cell.station, grasp_cell.context
    plant, plant_context = station.plant(), station.plant_context(context)
    result = ledger.result
    if result.end_reason != DIVERGED:  # (a diverged state has no finite poses to tell)
        for k, body in enumerate(station.object_bodies):
            if ledger.present[k]:
                p_WO = plant.EvalBodyPoseInWorld(plant_context, body).translation()
                result.objects_left.append({"object": ledger.object_names[k],
                                            "p_WO": [round(float(v), 3) for v in p_WO]})
    result.sim_time_s = context.get_time()
    return result


def _grasp_until_done(grasp_cell: GraspCell, ledger: EpisodeLedger,
                      on_attempt: Callable[[int, dict], None] | None) -> None:
    """Attempts until the ledger or the executive ends the run (its reason in `ledger.result`)."""
    station, context = grasp_cell.station, grasp_cell.context
    plant, plant_context = station.plant(), station.plant_context(context)
    while True:
        task = run_attempt(grasp_cell)
        if task.mode is Mode.NO_OBJECTS:
            ledger.result.end_reason = NO_OBJECTS_IN_VIEW
            return
        if task.mode in END_MODES:
            ledger.end_early(task.mode.value)
            return
        entry = ledger.record(task.attempt, context.get_time())
        if on_attempt is not None:
            on_attempt(ledger.actions, entry)
        # The arm is home: take the grasped object from the hand (into the bin) and
        # fallen objects out of the scene.
        ledger.remove_fallen([plant.EvalBodyPoseInWorld(plant_context, b).translation()[2]
                              for b in station.object_bodies])
        for k in np.flatnonzero(~ledger.present):
            park_object(plant, plant_context, station.object_bodies[k], int(k))
        reason = ledger.end_reason()
        if reason is not None:
            ledger.result.end_reason = reason
            return
        grasp_cell.executive.start_next_attempt(context, RESETTLE_S if task.attempt.planned else 0.0)


def _attempt_in_flight(state: ExecutiveState) -> Attempt | None:
    """The attempt the executive was executing (planned, not yet recorded), as failed by divergence."""
    if state.attempt is None or not state.attempt.planned or state.mode not in EXECUTING:
        return None
    return dc.replace(state.attempt, success=False, failure=DIVERGED)
