"""Closed-loop grasping in physics: observe, sample, rank by a policy, plan, execute, lift.

Runs N seeded episodes of an evaluation and prints, per run and in aggregate, the paper's
metrics: grasp success rate (successful grasps / attempts), completion rate (objects
grasped / objects), planning success rate (successful plans / plans tried), attempts, and
simulated and wall time; and the cell's own: wasted attempts (failed plans + repeated
failures), objects touched in transit, and the runs that ended early with "nothing
reachable". An evaluation is typed configuration (`drake_grasp.evaluation.config`):
`--config paper` runs the paper's policy and loop exactly, `--config FILE.yaml` any
other; the options below override its fields. Runs go to worker processes (one per core
by default); a bar shows runs, attempts and the running grasp success (on a terminal,
unless --quiet). A run whose simulation diverges starts over at half the physics step; one
that diverges again ends there and is kept, with its reason; a run that fails otherwise is
reported and the others go on.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses as dc
import functools
import multiprocessing
import os
import queue
import sys
import time
from collections.abc import Callable

from drake_grasp.apps.cli import (
    add_sampler_option,
    fail,
    failed_run_line,
    non_negative_int,
    note_contact_fill,
    out_file,
    positive_int,
    program_logging,
    sigterm_interrupts,
    simulation_worker,
)
from drake_grasp.datasets.shards import JobFailure, run_jobs
from drake_grasp.evaluation.config import EvaluationConfig, load_config, preset_names
from drake_grasp.evaluation.runs import (
    finished_runs,
    format_run,
    format_summary,
    report_header,
    run_one,
    summarize,
    write_report,
)
from drake_grasp.policy.scorers import POLICIES, make_scorer
from drake_grasp.robot.hand import known_hands
from drake_grasp.robot.object_files import MESH_UNITS
from drake_grasp.robot.specs import ROBOTS
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.scenario import scenario_names

RUN_SCENARIOS = [n for n in scenario_names() if n != "single"]


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp.simulate", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", default=None, metavar="PRESET|FILE",
                        help=f"the evaluation: a preset ({', '.join(preset_names())}) or a YAML file "
                             "(default: today's default)")
    parser.add_argument("--robot", help=f"one of {sorted(ROBOTS)} or an arm YAML file (default panda)")
    parser.add_argument("--hand", default=None, metavar="HAND",
                        help=f"one of {known_hands()} or a hand YAML file (default: the arm's hand)")
    parser.add_argument("--scenario",
                        help=f"one of {RUN_SCENARIOS} or a scenario YAML file (default standard)")
    parser.add_argument("--policy", help=f"one of {sorted(POLICIES)} (default cnn_rp, the paper's p_r * p_s)")
    parser.add_argument("--objects", help="object set: 'primitives', 'novel' or a folder of SDF/URDF/OBJ "
                                          "files (default: the scenario's set)")
    parser.add_argument("--object-units", choices=sorted(MESH_UNITS),
                        help="the lengths of the --objects folder's files (default m; mm: scaled by 0.001, "
                             "as CAD and scanned meshes often come)")
    parser.add_argument("--grasp-threshold", type=float, default=None, metavar="P",
                        help="end a run, 'nothing graspable', when the best untried candidate's p_s * p_h "
                             "is under P (default: the configuration's; 0: off)")
    parser.add_argument("--grip-force", type=float, default=None, metavar="N",
                        help="the hand grips force-controlled, pressing the object with N newtons a finger "
                             "whatever its width, as a Franka hand's grasp action (up to 140; default: the "
                             "scenario's grip, a spring of up to 20 N)")
    add_sampler_option(parser, None)
    parser.add_argument("--runs", type=positive_int, help="runs (default 1)")
    parser.add_argument("--seed", type=non_negative_int, help="run k uses seed + k (default 0)")
    parser.add_argument("--depth-noise", action="store_true", default=None,
                        help="the depth camera with its noise model (drake_grasp.simulation.depth_noise)")
    parser.add_argument("--workers", type=positive_int, default=None,
                        help="worker processes (default: one per core, at most --runs)")
    parser.add_argument("--meshcat", action="store_true",
                        help="show the scene, the candidates and the chosen grasp in Meshcat")
    parser.add_argument("--report", type=out_file, default=None,
                        help="write the metrics as JSON here, after every run; a report of the same "
                             "experiment that is already there is resumed (its finished runs are kept; "
                             "remove it to start over)")
    parser.add_argument("-v", "--verbose", action="store_true", help="print every attempt")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    return parser.parse_args(argv)


def evaluation_config(args: argparse.Namespace) -> EvaluationConfig:
    """The configuration `--config` names, with the options given on the command line over it."""
    config = load_config(args.config)
    fields = ("robot", "hand", "scenario", "policy", "objects", "object_units", "runs", "seed", "depth_noise",
              "grip_force", "sampler")
    given = {field: getattr(args, field) for field in fields if getattr(args, field) is not None}
    config = dc.replace(config, **given)
    if args.grasp_threshold is not None:
        config = dc.replace(config, loop=dc.replace(config.loop, grasp_threshold=args.grasp_threshold))
    config.check()
    return config


_progress: queue.Queue | None = None  # a worker's channel to the main process's bar: (seed, success)


def _init_worker(progress: queue.Queue | None, workers: int) -> None:
    global _progress
    simulation_worker(workers)
    _progress = progress


def _run(config: EvaluationConfig, seed: int, verbose: bool) -> dict:
    return run_one(config, seed, verbose=verbose, progress=_progress)


class RunProgress:
    """A bar over the runs, with the attempts so far and their grasp success (off: plain lines)."""

    def __init__(self, total: int, *, done: int, enabled: bool):
        self.enabled = enabled
        self._by_seed: dict[int, list[int]] = {}  # the attempts and successes counted of each run
        self._bar = None
        if enabled:
            from tqdm import tqdm

            self._bar = tqdm(total=total, initial=done, unit="run", dynamic_ncols=True)

    @property
    def attempts(self) -> int:
        return sum(counted[0] for counted in self._by_seed.values())

    @property
    def successes(self) -> int:
        return sum(counted[1] for counted in self._by_seed.values())

    def drain(self, progress: queue.Queue | None) -> None:
        """Counts the attempts the workers have reported since the last call; a run that started over
        (its seed with None) takes back the attempts of its first try."""
        if progress is None:
            return
        while True:
            try:
                seed, success = progress.get_nowait()
            except queue.Empty:
                break
            counted = self._by_seed.setdefault(seed, [0, 0])
            counted[:] = [0, 0] if success is None else [counted[0] + 1, counted[1] + success]
        attempts = self.attempts
        if self._bar is not None and attempts:
            self._bar.set_postfix_str(f"attempts {attempts}, grasp success {self.successes / attempts:.1%}")

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


def run_in_workers(config: EvaluationConfig, seeds: list[int], workers: int, verbose: bool, bar: RunProgress,
                   finished: Callable[[dict], None], failed: list[int]) -> None:
    """Runs `seeds` in `workers` processes, handing each finished run to `finished` and adding the seed
    of each run that failed to `failed` (one run's bug must not cost the others). Bad input
    (ValueError) ends them all; on an interrupt the runs in flight are dropped, not waited for."""
    # A run depends only on its seed (the planner seeds every OMPL query itself),
    # so workers may take several runs each.
    progress = multiprocessing.get_context("spawn").Queue() if bar.enabled else None
    results = run_jobs(functools.partial(_run, config, verbose=verbose), seeds, workers=workers,
                       worker_init=functools.partial(_init_worker, progress, workers),
                       poll=functools.partial(bar.drain, progress), keep_going=True)
    with contextlib.closing(results):
        for seed, run in results:
            if isinstance(run, JobFailure):
                failed.append(seed)
                bar.write(failed_run_line(f"run seed={seed:>4}", run), file=sys.stderr)
            else:
                finished(run)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    program_logging()
    try:
        config = evaluation_config(args)
        robot = config.robot_spec()
        make_scorer(config.policy, robot, config.selection)
        scenario = config.load_scenario()
        config = dc.replace(config, objects=config.object_set())
        note_contact_fill(load_object_set(config.objects, config.object_units))
        header = report_header(config)
        runs = finished_runs(args.report, header)
    except ValueError as e:
        return fail(e)
    seeds = config.seeds
    done = {r["seed"] for r in runs}
    pending = [seed for seed in seeds if seed not in done]
    workers = min(args.workers or os.cpu_count() or 1, max(1, len(pending)))
    print(f"drake_grasp.simulate: robot={robot.name} scenario={scenario.name} policy={config.policy} "
          f"runs={config.runs} workers={workers}", flush=True)
    if runs:
        print(f"resuming {args.report}: {len(runs)} of {config.runs} runs already done", flush=True)
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
        with sigterm_interrupts():
            if args.meshcat:  # one process, so that one Meshcat shows every run
                from pydrake.geometry import StartMeshcat

                meshcat = StartMeshcat()
                print(f"Meshcat: {meshcat.web_url()}", flush=True)
                for seed in pending:
                    finished(run_one(config, seed, verbose=args.verbose, meshcat=meshcat))
            elif pending:
                run_in_workers(config, pending, workers, args.verbose, bar, finished, failed)
    except KeyboardInterrupt:
        bar.close()
        print(f"interrupted after {len(runs)} of {config.runs} runs"
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
    wall_s = time.perf_counter() - wall_start
    print(("partial " if interrupted else "") + format_summary(summary, len(runs), wall_s))
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
