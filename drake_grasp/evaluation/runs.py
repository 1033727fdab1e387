"""An evaluation's runs: one seeded run (episode) of its configuration, and the report that holds them.

A report is the configuration written whole (`EvaluationConfig.experiment`), the robot's and the
scenario's names, the digests of the weights files the policy loads and a format number, then the
aggregates and the runs. A report resumes only a run of the very same header: another configuration,
other weights or another format is another experiment.
"""

from __future__ import annotations

import dataclasses as dc
import json
import logging
import queue
from pathlib import Path

import numpy as np

from drake_grasp.evaluation.config import EvaluationConfig
from drake_grasp.evaluation.stats import mean_ci95
from drake_grasp.simulation.divergence import DIVERGED
from drake_grasp.simulation.scenario import Scenario

_log = logging.getLogger(__name__)

REPORT_FORMAT = 3
NOTHING_REACHABLE = "nothing reachable"
NOTHING_GRASPABLE = "nothing graspable"
RATES = ("grasp_success_rate", "completion_rate", "planning_success_rate")


def executive_config(config: EvaluationConfig):
    """The executive's options: the paper's loop, or failure memory, the early stop at the threshold
    calibrated on the arm's RP card (for the policies that predict p_r: the others have no such stop,
    so an arm needs no RP to run them) and the evaluation's "nothing graspable" threshold."""
    from drake_grasp.cell.executive import CellConfig
    from drake_grasp.learning.rp import ReachabilityPredictor, rp_weights

    if config.loop.paper_loop:
        base = CellConfig.paper()
    else:
        robot = config.robot_spec()
        uses_rp = config.policy in ("rp", "cnn_rp")
        threshold = ReachabilityPredictor.load(str(rp_weights(robot))).stop_threshold if uses_rp else 0.0
        base = CellConfig(reach_threshold=threshold, grasp_threshold=config.loop.grasp_threshold)
    return dc.replace(base, avoid_observed_objects=not config.loop.transit_ignores_objects)


def report_header(config: EvaluationConfig) -> dict:
    """What a report of `config` records and what resuming it must match, whole."""
    from drake_grasp.learning.weights import weights_digest
    from drake_grasp.policy.scorers import policy_weights
    from drake_grasp.robot.hand import hand_record

    robot = config.robot_spec()
    weights = policy_weights(config.policy, robot, config.selection)
    scenario = config.load_scenario()
    rules = run_rules_of(scenario)
    return {"format": REPORT_FORMAT, "robot_name": robot.name, "hand": hand_record(robot.hand),
            "scenario_name": scenario.name,
            "evaluation": config.experiment(), "physics": physics_of(scenario),
            **({"run_rules": rules} if rules else {}),
            "weights": {path.name: weights_digest(path) for path in weights}}


# `Scenario`'s rules of a run: how a grasp is judged and what ends the run
RUN_RULES = ("success_rule", "max_attempts", "max_consecutive_failures", "max_consecutive_plan_failures")


def run_rules_of(scenario: Scenario) -> dict:
    """How a run of `scenario` is judged and ended (`RUN_RULES`), where its file sets it otherwise than a
    scenario's default: the file may change between reports, and a run under one rule is not one under
    another."""
    default = Scenario()
    return {rule: getattr(scenario, rule) for rule in RUN_RULES
            if getattr(scenario, rule) != getattr(default, rule)}


def physics_of(scenario: Scenario) -> dict:
    """The physics a run of `scenario` steps with (the scenario's file may change between reports); the
    grip only when force-controlled (`ControlConfig.grip_force`): the spring grip's reports stay as they
    were."""
    grip = scenario.control.grip_force
    return {"time_step": scenario.plant_config.time_step, "object_sleep": scenario.object_sleep.enabled,
            **({"grip_force": grip} if grip is not None else {})}


def run_one(config: EvaluationConfig, seed: int, *, verbose: bool = False, meshcat=None,
            progress: queue.Queue | None = None, settled_folder: str | None = None) -> dict:
    """One seeded run (episode) of `config`, as the report's dict; each attempt's (seed, success) goes
    to `progress` when given, and (seed, None) when the run starts over (its attempts so far no longer
    count). With `settled_folder`, the dropped scene is shared with the runs of other policies on the
    same scene that use the same folder (`drake_grasp.simulation.settled`)."""
    from drake_grasp.cell.episode import run_episode
    from drake_grasp.policy.scorers import make_scorer
    from drake_grasp.simulation.objects import load_object_set
    from drake_grasp.simulation.settled import SettledScenes

    robot = config.robot_spec()
    scenario = config.load_scenario()

    def log(k: int, entry: dict) -> None:
        push = entry.get("push", False)
        if progress is not None and not push:
            progress.put((seed, bool(entry["success"])))
        if verbose and push:
            outcome = "moved an object" if entry["success"] else entry["failure"]
            plan_ms = entry["plan_seconds"] * 1e3
            _log.info(f"  seed {seed} action {k}: push, {outcome} (plan {plan_ms:.0f} ms)")
        elif verbose:
            outcome = "success" if entry["success"] else entry["failure"]
            if entry["planned"]:
                outcome += f" ({entry.get('object')} rose {entry['rise'] * 100:.1f} cm)"
            if entry["repeat"]:
                outcome += " [repeat]"
            _log.info(f"  seed {seed} attempt {k}: {outcome} (plan {entry['plan_seconds'] * 1e3:.0f} ms, "
                      f"gamma {entry['approach_angle_deg']:.0f} deg)")

    result = run_episode(robot=robot, scenario=scenario,
                         scorer=make_scorer(config.policy, robot, config.selection),
                         object_models=load_object_set(config.object_set(), config.object_units), seed=seed,
                         cell=executive_config(config), meshcat=meshcat, on_attempt=log,
                         on_restart=None if progress is None else lambda: progress.put((seed, None)),
                         settled=None if settled_folder is None else SettledScenes(settled_folder))
    run = result.to_dict()
    if verbose and result.diverged_try is not None:
        _log.info(f"  seed {seed}: {half_step_note(run)} ({result.diverged_try['divergence']})")
    return run


def summarize(runs: list[dict]) -> dict:
    """Aggregates: the mean of per-run rates (as the paper reports), and pooled counts."""
    def mean(key: str) -> float:
        return float(np.mean([r[key] for r in runs])) if runs else 0.0

    attempts = sum(r["attempts"] for r in runs)
    plans_tried = sum(r["plans_tried"] for r in runs)
    return {
        **{rate: mean(rate) for rate in RATES},
        "ci95": {rate: mean_ci95([r[rate] for r in runs])[1] for rate in RATES},
        "pooled": {
            "attempts": attempts,
            "successes": sum(r["successes"] for r in runs),
            "grasp_success_rate": sum(r["successes"] for r in runs) / attempts if attempts else 0.0,
            "planning_success_rate": (sum(r["plans_succeeded"] for r in runs) / plans_tried
                                      if plans_tried else 0.0),
            "objects_grasped": sum(r["objects_grasped"] for r in runs),
            "objects": sum(r["num_objects"] for r in runs),
        },
        "attempts_per_run": mean("attempts"),
        "pushes": sum(r.get("pushes", 0) for r in runs),
        "pushes_moved": sum(r.get("pushes_moved", 0) for r in runs),
        "wasted_attempts": sum(r["wasted_attempts"] for r in runs),
        "repeated_failures": sum(r["repeated_failures"] for r in runs),
        "transit_contacts": sum(r["transit_contacts"] for r in runs),
        "unplanned_returns": sum(r["unplanned_returns"] for r in runs),
        "ended_nothing_reachable": sum(r["end_reason"] == NOTHING_REACHABLE for r in runs),
        "ended_nothing_graspable": sum(r["end_reason"] == NOTHING_GRASPABLE for r in runs),
        "ended_diverged": sum(r["end_reason"] == DIVERGED for r in runs),
        "ran_at_half_step": sum(r.get("diverged_try") is not None for r in runs),
        "attempts_saved": sum(r["attempts_saved"] for r in runs),
        "wall_time_per_run_s": mean("wall_time_s"),
        "sim_time_s": sum(r["sim_time_s"] for r in runs),
        "wall_time_s": sum(r["wall_time_s"] for r in runs),
    }


def finished_runs(report: Path | None, header: dict) -> list[dict]:
    """The runs an existing report of the same experiment already holds (to resume it; runs of other
    seeds stay in the report too); ValueError when it holds another experiment."""
    if report is None or not report.exists():
        return []
    try:
        old = json.loads(report.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"cannot read the existing report {report}: {e}") from None
    differing = sorted(key for key in header if old.get(key) != header[key])
    if differing:
        raise ValueError(f"{report} holds another experiment (its {', '.join(differing)} differ); "
                         "pass another --report or remove it")
    return list(old.get("runs", []))


def write_report(path: Path, header: dict, seeds: list[int], runs: list[dict]) -> None:
    """The report of the runs so far (sorted by seed), written atomically. It lists the seeds asked for
    and those of the runs it holds, and is complete when it holds a run of each."""
    runs = sorted(runs, key=lambda r: r["seed"])
    done = {r["seed"] for r in runs}
    seeds = sorted(set(seeds) | done)
    report = {**header, "seeds": seeds, "complete": done >= set(seeds), **summarize(runs), "runs": runs}
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(path.suffix + ".partial")
    partial.write_text(json.dumps(report, indent=1))
    partial.replace(path)


def pm(ci95: float) -> str:
    """' +- 1.2%', or nothing where one run gives no interval."""
    return f" +- {ci95:.1%}" if np.isfinite(ci95) else ""


def format_run(r: dict) -> str:
    """One run's line."""
    return (f"run seed={r['seed']:>4}: grasp success {r['grasp_success_rate']:6.1%}  "
            f"completion {r['completion_rate']:6.1%}  planning success {r['planning_success_rate']:6.1%}  "
            f"attempts {r['attempts']:>3}{_pushes(r)}  wasted {r['wasted_attempts']:>2}  "
            f"sim {r['sim_time_s']:6.1f} s  wall {r['wall_time_s']:6.1f} s  "
            f"({r['end_reason']}{': ' + r['divergence'] if r.get('divergence') else ''})"
            f"{f' [{half_step_note(r)}]' if r.get('diverged_try') else ''}")


def half_step_note(r: dict) -> str:
    """'ran at 2 ms after diverging at 4 ms', for a run that started over at half the step."""
    step_ms = r["diverged_try"]["time_step"] * 1e3
    return f"ran at {step_ms / 2:g} ms after diverging at {step_ms:g} ms"


def _pushes(r: dict) -> str:
    """'  pushes 12 (moved 9)' for a policy that pushes; nothing otherwise."""
    return f"  pushes {r['pushes']} (moved {r['pushes_moved']})" if r.get("pushes") else ""


def format_summary(summary: dict, runs: int, wall_s: float) -> str:
    """The aggregate line (means over runs with their 95 % intervals, the counts)."""
    ci = summary["ci95"]
    return (f"aggregate over {runs} runs (mean +- 95 % CI): "
            f"grasp success {summary['grasp_success_rate']:.1%}{pm(ci['grasp_success_rate'])}  "
            f"completion {summary['completion_rate']:.1%}{pm(ci['completion_rate'])}  "
            f"planning success {summary['planning_success_rate']:.1%}{pm(ci['planning_success_rate'])}  "
            f"attempts/run {summary['attempts_per_run']:.1f}{_pushes(summary)}  "
            f"wasted attempts {summary['wasted_attempts']}  "
            f"transit contacts {summary['transit_contacts']}  "
            f"ended 'nothing reachable' {summary['ended_nothing_reachable']}, "
            f"'nothing graspable' {summary['ended_nothing_graspable']} "
            f"(saved {summary['attempts_saved']}), diverged {summary['ended_diverged']} "
            f"({summary['ran_at_half_step']} ran again at half the step)  "
            f"sim {summary['sim_time_s']:.1f} s  wall {wall_s:.1f} s")
