"""Closed-loop grasping in physics: observe, sample, rank by a policy, plan, execute, lift.

Runs N seeded episodes of a scenario and prints, per run and in aggregate, the
paper's metrics: grasp success rate (successful grasps / attempts), completion
rate (objects grasped / objects), planning success rate (successful plans /
plans tried), attempts, and simulated and wall time; and the cell's own: wasted
attempts (failed plans + repeated failures), objects touched in transit, and the
runs that ended early with "nothing reachable". Runs go to worker processes (one
per core by default); a bar shows runs, attempts and the running grasp success
(on a terminal, unless --quiet). A run whose simulation diverges ends there and is
kept, with its reason; a run that fails otherwise is reported and the others go on.
"""

from __future__ import annotations

import argparse
import dataclasses as dc
import json
import multiprocessing
import os
import queue
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from pathlib import Path

import numpy as np

from drake_grasp.apps.cli import (
    add_selection_option,
    fail,
    header_fields,
    note_contact_fill,
    out_file,
    positive_float,
    positive_int,
    quiet_drake,
    score_threshold,
    selection_config,
)
from drake_grasp.learning.weights import weights_digest
from drake_grasp.policy.episode import NOTHING_GRASPABLE, NOTHING_REACHABLE
from drake_grasp.policy.executive import CellConfig
from drake_grasp.policy.scorers import (
    POLICIES,
    USES_CNN,
    SelectionConfig,
    make_scorer,
    policy_scenario,
    policy_weights,
)
from drake_grasp.robots import ROBOTS, get_robot
from drake_grasp.simulation.config import DEFAULT_TIME_STEP
from drake_grasp.simulation.divergence import DIVERGED, first_line
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.scenario import Scenario, load_scenario, scenario_names
from drake_grasp.stats import mean_ci95

RUN_SCENARIOS = [n for n in scenario_names() if n != "single"]


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp.simulate", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="panda",
                        help=f"one of {sorted(ROBOTS)} or an arm YAML file (default panda)")
    parser.add_argument("--scenario", default="standard",
                        help=f"one of {RUN_SCENARIOS} or a scenario YAML file (default standard)")
    parser.add_argument("--policy", default="cnn_rp",
                        help=f"one of {sorted(POLICIES)} (default cnn_rp, the paper's p_r * p_s)")
    parser.add_argument("--runs", type=positive_int, default=1)
    parser.add_argument("--seed", type=int, default=0, help="run k uses seed + k")
    parser.add_argument("--objects", default=None,
                        help="object set: 'primitives', 'novel' or a folder of SDF/URDF/OBJ files "
                             "(default: the scenario's set)")
    parser.add_argument("--workers", type=positive_int, default=None,
                        help="worker processes (default: one per core, at most --runs)")
    parser.add_argument("--paper-loop", action="store_true",
                        help="the paper's loop: no failure memory (a grasp that failed may be tried again) "
                             "and no early stop when nothing is reachable")
    parser.add_argument("--grasp-threshold", type=score_threshold, default=0.0, metavar="SCORE",
                        help="end the run, 'nothing graspable', when the best untried candidate's score "
                             "is under SCORE (policies that score stability; default 0: off)")
    parser.add_argument("--transit-ignores-objects", action="store_true",
                        help="plan the transit against the robot and table only, not the observed objects")
    parser.add_argument("--depth-noise", action="store_true",
                        help="the depth camera with its noise model (drake_grasp.simulation.depth_noise)")
    parser.add_argument("--max-attempts", type=positive_int, default=None,
                        help="end each run after this many attempts (default: as the scenario says)")
    parser.add_argument("--object-sleep", choices=("on", "off"), default=None,
                        help="lock objects at rest away from the hand, for speed (default: as the scenario "
                             "says; drake_grasp.simulation.sleep)")
    parser.add_argument("--time-step", type=positive_float, default=None, metavar="SECONDS",
                        help="the physics step (default: as the scenario says, "
                             f"{DEFAULT_TIME_STEP} s unless it names another)")
    add_selection_option(parser)
    parser.add_argument("--top-grasp", action="store_true",
                        help="candidates approach straight down only (the paper's top-grasping variant)")
    parser.add_argument("--meshcat", action="store_true",
                        help="show the scene, the candidates and the chosen grasp in Meshcat")
    parser.add_argument("--report", type=out_file, default=None,
                        help="write the metrics as JSON here, after every run; a report of the same "
                             "experiment that is already there is resumed (its finished runs are kept)")
    parser.add_argument("--fresh", action="store_true", help="start over instead of resuming --report")
    parser.add_argument("-v", "--verbose", action="store_true", help="print every attempt")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    return parser.parse_args(argv)


def cell_config(robot_source: str, policy: str, *, paper_loop: bool, transit_ignores_objects: bool,
                grasp_threshold: float = 0.0) -> CellConfig:
    """The cell's options; the early stop uses the threshold calibrated on the arm's RP card (for the
    policies that predict p_r: the others have no early stop, so an arm needs no RP to run them).
    `grasp_threshold` applies to the policies whose score holds p_s (a ValueError for the others)."""
    from drake_grasp.learning.rp import ReachabilityPredictor

    if grasp_threshold and policy not in USES_CNN:
        raise ValueError(f"--grasp-threshold needs a policy that scores stability "
                         f"({', '.join(sorted(USES_CNN))}), not '{policy}'")
    if grasp_threshold and paper_loop:
        raise ValueError("--grasp-threshold with --paper-loop: the paper's loop has no early stop")
    threshold = ReachabilityPredictor.load(robot_source).stop_threshold if policy in ("rp", "cnn_rp") else 0.0
    base = CellConfig.paper() if paper_loop else CellConfig(reach_threshold=threshold,
                                                            grasp_threshold=grasp_threshold)
    return dc.replace(base, avoid_observed_objects=not transit_ignores_objects)


@dc.dataclass(frozen=True)
class RunSpec:
    """What one cell of an evaluation runs: everything but the seed."""

    robot: str  # a robot's source (name or arm YAML)
    scenario: str
    policy: str
    objects: str | None
    cell: CellConfig
    depth_noise: bool = False
    top_grasp: bool = False  # approach straight down only (gamma1 = gamma2 = 0), the paper's "top grasping"
    object_sleep: bool | None = None  # objects at rest sleep (None: as the scenario file says)
    max_attempts: int | None = None  # attempts per run (None: as the scenario file says)
    time_step: float | None = None  # the physics step [s] (None: as the scenario file says)
    selection: SelectionConfig = SelectionConfig()  # how the CNN policies spend the CNN

    def load_scenario(self) -> Scenario:
        scenario = policy_scenario(self.policy, load_scenario(self.scenario))
        if self.depth_noise:  # (else as the scenario file says)
            scenario = scenario.with_depth_noise()
        if self.object_sleep is not None:
            scenario = scenario.with_object_sleep(self.object_sleep)
        if self.max_attempts is not None:
            scenario = dc.replace(scenario, max_attempts=self.max_attempts)
        if self.time_step is not None:
            scenario = scenario.with_time_step(self.time_step)
        return dc.replace(scenario, gamma_deg=[0.0, 0.0]) if self.top_grasp else scenario

    def header(self, robot_name: str) -> dict:
        """What a report of this cell records and what resuming it must match."""
        scenario = self.load_scenario()
        header = {"robot": robot_name, "scenario": scenario.name, "policy": self.policy,
                  "objects": self.objects or scenario.object_set,
                  "cell": header_fields(self.cell, added_later={"grasp_threshold": 0.0})}
        # (Only when set: the reports of the plain experiment keep their header.)
        if scenario.depth_noise.enabled:
            header["depth_noise"] = dc.asdict(scenario.depth_noise)
        if self.top_grasp:
            header["top_grasp"] = True
        if scenario.object_sleep.enabled:
            header["object_sleep"] = dc.asdict(scenario.object_sleep)
        if self.max_attempts is not None:
            header["max_attempts"] = self.max_attempts
        if scenario.settle_within > 0:
            header["settle_within"] = scenario.settle_within
        if scenario.plant_config.time_step != DEFAULT_TIME_STEP:
            header["time_step"] = scenario.plant_config.time_step
        if self.policy in USES_CNN:  # which CNN and hold predictor (a report of another's is not resumed)
            selection = header_fields(self.selection,
                                      added_later={"finger_symmetry": False, "robust_top": 0,
                                                   "hold_z_scale": None, "hold_join_parts": False})
            header["selection"] = {k: v for k, v in selection.items() if v is not None}
        weights = policy_weights(self.policy, get_robot(self.robot), self.selection)
        if weights:  # the very files (retrained weights under the same name make another experiment)
            header["weights"] = {path.name: weights_digest(path) for path in weights}
        return header


_progress: queue.Queue | None = None  # a worker's channel to the main process's bar: (seed, success)


def _init_worker(progress: queue.Queue | None) -> None:
    global _progress
    quiet_drake()
    _progress = progress


def run_one(spec: RunSpec, seed: int, verbose: bool = False, meshcat=None) -> dict:
    """One seeded run (episode) of a cell, as the report's dict; each attempt's outcome goes to the
    progress channel when the worker has one."""
    from drake_grasp.policy.episode import run_episode

    robot = get_robot(spec.robot)
    scenario = spec.load_scenario()
    policy, objects_arg = spec.policy, spec.objects
    models = load_object_set(objects_arg or scenario.object_set)

    def log(k: int, entry: dict) -> None:
        if _progress is not None:
            _progress.put((seed, bool(entry["success"])))
        if verbose:
            outcome = "success" if entry["success"] else entry["failure"]
            if entry["planned"]:
                outcome += f" ({entry.get('object')} rose {entry['rise'] * 100:.1f} cm)"
            if entry["repeat"]:
                outcome += " [repeat]"
            print(f"  seed {seed} attempt {k}: {outcome} (plan {entry['plan_seconds'] * 1e3:.0f} ms, "
                  f"gamma {entry['approach_angle_deg']:.0f} deg)", flush=True)

    result = run_episode(robot=robot, scenario=scenario, scorer=make_scorer(policy, robot, spec.selection),
                         object_models=models, seed=seed, cell=spec.cell, meshcat=meshcat, on_attempt=log)
    return result.to_dict()


def summarize(runs: list[dict]) -> dict:
    """Aggregates: the mean of per-run rates (as the paper reports), and pooled counts."""
    def mean(key: str) -> float:
        return float(np.mean([r[key] for r in runs])) if runs else 0.0

    attempts = sum(r["attempts"] for r in runs)
    plans_tried = sum(r["plans_tried"] for r in runs)
    rates = ("grasp_success_rate", "completion_rate", "planning_success_rate")
    return {
        **{rate: mean(rate) for rate in rates},
        "ci95": {rate: mean_ci95([r[rate] for r in runs])[1] for rate in rates},
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
        "wasted_attempts": sum(r["wasted_attempts"] for r in runs),
        "repeated_failures": sum(r["repeated_failures"] for r in runs),
        "transit_contacts": sum(r["transit_contacts"] for r in runs),
        "unplanned_returns": sum(r["unplanned_returns"] for r in runs),
        "ended_nothing_reachable": sum(r["end_reason"] == NOTHING_REACHABLE for r in runs),
        "ended_nothing_graspable": sum(r["end_reason"] == NOTHING_GRASPABLE for r in runs),
        "ended_diverged": sum(r["end_reason"] == DIVERGED for r in runs),
        "attempts_saved": sum(r["attempts_saved"] for r in runs),
        "wall_time_per_run_s": mean("wall_time_s"),
        "sim_time_s": sum(r["sim_time_s"] for r in runs),
        "wall_time_s": sum(r["wall_time_s"] for r in runs),
    }


def finished_runs(report: Path | None, header: dict) -> list[dict]:
    """The runs an existing report of the same experiment already holds (to resume it; runs of other
    seeds stay in the report too)."""
    if report is None or not report.exists():
        return []
    try:
        old = json.loads(report.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"cannot read the existing report {report}: {e}") from None
    # Each of these makes another experiment:
    variants = {"depth_noise", "top_grasp", "object_sleep", "max_attempts", "selection", "settle_within",
                "time_step"}
    keys = set(header) | (variants & set(old))
    if "weights" not in old:  # a report from before the weights' digests were recorded
        keys.discard("weights")
    differing = sorted(key for key in keys if old.get(key) != header.get(key))
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


def format_run(r: dict) -> str:
    return (f"run seed={r['seed']:>4}: grasp success {r['grasp_success_rate']:6.1%}  "
            f"completion {r['completion_rate']:6.1%}  planning success {r['planning_success_rate']:6.1%}  "
            f"attempts {r['attempts']:>3}  wasted {r['wasted_attempts']:>2}  "
            f"sim {r['sim_time_s']:6.1f} s  wall {r['wall_time_s']:6.1f} s  "
            f"({r['end_reason']}{': ' + r['divergence'] if r.get('divergence') else ''})")


class RunProgress:
    """A bar over the runs, with the attempts so far and their grasp success (off: plain lines)."""

    def __init__(self, total: int, *, done: int, enabled: bool):
        self.enabled = enabled
        self.attempts = self.successes = 0
        self._bar = None
        if enabled:
            from tqdm import tqdm

            self._bar = tqdm(total=total, initial=done, unit="run", dynamic_ncols=True)

    def drain(self, progress: queue.Queue | None) -> None:
        """Counts the attempts the workers have reported since the last call."""
        if progress is None:
            return
        while True:
            try:
                _, success = progress.get_nowait()
            except queue.Empty:
                break
            self.attempts += 1
            self.successes += success
        self._show()

    def advance(self) -> None:
        """One more run done."""
        if self._bar is not None:
            self._bar.update(1)

    def write(self, line: str, file=None) -> None:
        if self._bar is not None:
            self._bar.write(line, file=file)
        else:
            print(line, file=file, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def _show(self) -> None:
        if self._bar is not None and self.attempts:
            self._bar.set_postfix_str(f"attempts {self.attempts}, grasp success "
                                      f"{self.successes / self.attempts:.1%}")


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    quiet_drake()
    try:
        robot = get_robot(args.robot)
        make_scorer(args.policy, robot, selection_config(args))
        if args.scenario == "single":
            raise ValueError("scenario 'single' is for data collection; choose one of: "
                             + ", ".join(RUN_SCENARIOS))
        scenario = load_scenario(args.scenario)
        note_contact_fill(load_object_set(args.objects or scenario.object_set))
    except ValueError as e:
        return fail(e)
    seeds = [args.seed + k for k in range(args.runs)]
    try:
        cell = cell_config(robot.source, args.policy, paper_loop=args.paper_loop,
                           transit_ignores_objects=args.transit_ignores_objects,
                           grasp_threshold=args.grasp_threshold)
    except ValueError as e:
        return fail(e)
    spec = RunSpec(robot.source, args.scenario, args.policy, args.objects, cell, depth_noise=args.depth_noise,
                   object_sleep=None if args.object_sleep is None else args.object_sleep == "on",
                   max_attempts=args.max_attempts, time_step=args.time_step, top_grasp=args.top_grasp,
                   selection=selection_config(args))
    header = spec.header(robot.name)
    try:
        runs = [] if args.fresh else finished_runs(args.report, header)
    except ValueError as e:
        return fail(e)
    done = {r["seed"] for r in runs}
    pending = [seed for seed in seeds if seed not in done]
    workers = min(args.workers or os.cpu_count() or 1, max(1, len(pending)))
    print(f"drake_grasp.simulate: robot={robot.name} scenario={scenario.name} policy={args.policy} "
          f"runs={args.runs} workers={workers}", flush=True)
    if runs:
        print(f"resuming {args.report}: {len(runs)} of {args.runs} runs already done", flush=True)
    wall_start = time.perf_counter()
    interrupted = False
    failed: list[int] = []
    bar = RunProgress(len(seeds), done=len(runs), enabled=not args.quiet and sys.stderr.isatty())

    def finished(run: dict) -> None:
        runs.append(run)
        bar.advance()
        bar.write(format_run(run))
        if args.report is not None:  # after every run: an interrupted evaluation loses nothing
            write_report(args.report, header, seeds, runs)

    try:
        if args.meshcat:  # one process, so that one Meshcat shows every run
            from pydrake.geometry import StartMeshcat

            meshcat = StartMeshcat()
            print(f"Meshcat: {meshcat.web_url()}", flush=True)
            for seed in pending:
                finished(run_one(spec, seed, args.verbose, meshcat))
        elif pending:
            # A run depends only on its seed (the planner seeds every OMPL query itself),
            # so workers may take several runs each.
            ctx = multiprocessing.get_context("spawn")
            progress = ctx.Queue() if bar.enabled else None
            with ProcessPoolExecutor(workers, mp_context=ctx, initializer=_init_worker,
                                     initargs=(progress,)) as pool:
                futures = {pool.submit(run_one, spec, seed, args.verbose): seed for seed in pending}
                while futures:
                    done, _ = wait(futures, timeout=0.5, return_when=FIRST_COMPLETED)
                    bar.drain(progress)
                    for future in done:
                        seed = futures.pop(future)
                        try:
                            finished(future.result())
                        except Exception as e:  # one run's bug must not cost the others
                            failed.append(seed)
                            bar.write(f"run seed={seed:>4}: failed: {type(e).__name__}: {first_line(e)}",
                                      file=sys.stderr)
    except KeyboardInterrupt:
        bar.close()
        print(f"interrupted after {len(runs)} of {args.runs} runs"
              + (f"; rerun the same command to resume {args.report}" if args.report else ""), file=sys.stderr)
        interrupted = True
        if not runs:
            return 130
    except ValueError as e:
        bar.close()
        return fail(e)
    bar.close()
    runs.sort(key=lambda r: r["seed"])
    summary = summarize(runs)
    ci = summary["ci95"]
    print(f"{'partial ' if interrupted else ''}aggregate over {len(runs)} runs (mean +- 95 % CI): "
          f"grasp success {summary['grasp_success_rate']:.1%} +- {ci['grasp_success_rate']:.1%}  "
          f"completion {summary['completion_rate']:.1%} +- {ci['completion_rate']:.1%}  "
          f"planning success {summary['planning_success_rate']:.1%} +- {ci['planning_success_rate']:.1%}  "
          f"attempts/run {summary['attempts_per_run']:.1f}  wasted attempts {summary['wasted_attempts']}  "
          f"transit contacts {summary['transit_contacts']}  "
          f"ended 'nothing reachable' {summary['ended_nothing_reachable']}, "
          f"'nothing graspable' {summary['ended_nothing_graspable']} "
          f"(saved {summary['attempts_saved']}), diverged {summary['ended_diverged']}  "
          f"sim {summary['sim_time_s']:.1f} s  wall {time.perf_counter() - wall_start:.1f} s")
    if args.report is not None:
        write_report(args.report, header, seeds, runs)
        print(f"report written to {args.report}")
    if interrupted:
        return 130
    if failed:
        print(f"error: {len(failed)} run(s) failed (seeds {', '.join(map(str, failed))}); the others are "
              "kept" + (f" in {args.report}; rerun the same command to retry them" if args.report else ""),
              file=sys.stderr)
        return 1
    if args.meshcat and sys.stdin.isatty():
        input("Meshcat stays up; press Enter to quit. ")
    return 0


if __name__ == "__main__":
    sys.exit(main())
