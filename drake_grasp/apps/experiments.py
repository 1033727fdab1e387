"""The paper's experiments in one command: a table of evaluations, N runs each, tables and charts.

    python -m drake_grasp experiments --robot panda --runs 30 --out reports/my_table

The table is typed configuration (`drake_grasp.evaluation.config.TableConfig`): by default the
preset `paper_table` (Fig. 7: RAND, GPD1c, GPD, VPG and the paper's policy in the standard
and challenging scenes; Table I: RAND, RP only, 3DCNN and the paper's policy in the ablation
scene; the "top grasping" variant, candidates straight down only, of each standard-scene
policy but VPG, whose grasps are straight down already), on today's default models and loop;
`--config FILE` any other. Every entry is a `simulate` report
(OUT/ROBOT_SCENARIO_POLICY[_top].json) written after every run, so the whole table resumes
where it stopped; the runs of all entries share one pool of worker processes (one per core)
or a Ray cluster (--ray-address), with one progress bar, ten seeds at a time and within those
the longest runs first (the challenging scene's 30 objects before the standard scene's 10), so
that every core stays busy to the end and a table cut short has runs in every entry. The entries
of a scene share each seed's drop: the first to run a seed settles its objects and keeps the
settled state, the others start from it (`drake_grasp.simulation.settled`; the same runs, without
simulating the drop again; on this machine's workers, not across a Ray cluster). At the end:
OUT/table.md (every rate as mean +- 95 % CI over runs, the
paper's number beside ours where it gives one), OUT/summary.json (the same, this invocation's
wall time and the run time of every run summed over the sessions that made them),
OUT/success_and_completion.png (paper Fig. 7) and OUT/ablation.png (Table I), also on Ctrl-C or
SIGTERM (of the runs finished so far); --table-only writes them and runs nothing. A run that fails
is named and the others go on (exit 1 at the end; the same command retries it).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses as dc
import functools
import json
import os
import sys
import tempfile
import time

from drake_grasp.apps.cli import (
    fail,
    failed_run_line,
    non_negative_int,
    out_folder,
    positive_int,
    program_logging,
    sigterm_interrupts,
    simulation_worker,
)
from drake_grasp.evaluation.config import EvaluationConfig, load_table, table_names
from drake_grasp.evaluation.runs import finished_runs, report_header, run_one, write_report
from drake_grasp.policy.scorers import make_scorer
from drake_grasp.robot.object_files import MESH_UNITS
from drake_grasp.simulation.objects import load_object_set


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp experiments", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", default="paper_table", metavar="PRESET|FILE",
                        help=f"the table: a preset ({', '.join(table_names())}) or a YAML file "
                             "(default paper_table)")
    parser.add_argument("--robot", default=None, help="a built-in arm or an arm YAML file (default: the "
                                                      "table's, panda)")
    parser.add_argument("--objects", default=None,
                        help="the object set or folder of every entry (default: the table's, else each "
                             "scenario's)")
    parser.add_argument("--object-units", choices=sorted(MESH_UNITS), default=None,
                        help="the lengths of the --objects folder's files (default m; mm: scaled by 0.001)")
    parser.add_argument("--runs", type=positive_int, default=None,
                        help="runs an entry (default: the table's)")
    parser.add_argument("--challenging-runs", type=positive_int, default=None,
                        help="runs per challenging entry (default: the table's, else --runs)")
    parser.add_argument("--seed", type=non_negative_int, default=0, help="run k of every entry uses seed + k")
    parser.add_argument("--workers", type=positive_int, default=None, help="default: one per core")
    parser.add_argument("--ray-address", default=None, help="run on a Ray cluster ('auto', 'ray://host:10001')")
    parser.add_argument("--table-only", action="store_true",
                        help="run nothing: write the table and charts of the reports in --out as they stand")
    parser.add_argument("--out", type=out_folder, required=True, help="the folder of the reports and tables")
    return parser.parse_args(argv)


def _run(job: tuple[int, EvaluationConfig, int], settled_folder: str | None = None) -> dict:
    program_logging()
    _, config, seed = job
    return run_one(config, seed, settled_folder=settled_folder)


SEED_ROUND = 10  # jobs go ten seeds of every entry at a time, longest first within the ten


def expected_cost(config: EvaluationConfig) -> int:
    """A run's relative cost, to start the longest first: the attempts it may take (its objects, or
    the scenario's limit) times the objects in physics."""
    scenario = config.load_scenario()
    attempts = min(scenario.num_objects, scenario.max_attempts or scenario.num_objects)
    return attempts * scenario.num_objects


def job_order(jobs: list[tuple[int, EvaluationConfig, int]]) -> list[tuple[int, EvaluationConfig, int]]:
    """Ten seeds at a time (run k of every entry before run k + 10 of any), longest first within them,
    and within an entry seed by seed: the first entry of a scenario settles each seed's scene while the
    others, which share the dropped scenes, wait for their turn."""
    entries = {i: config for i, config, _ in jobs}  # (each entry's scenario is read once)
    costs = {i: expected_cost(config) for i, config in entries.items()}
    return sorted(jobs, key=lambda job: ((job[2] - job[1].seed) // SEED_ROUND, -costs[job[0]], job[0],
                                         job[2]))


def report_name(robot: str, config: EvaluationConfig) -> str:
    """ROBOT_SCENARIO_POLICY[_top][_WEIGHTS].json, the weights' name only where they are not the default's."""
    from pathlib import Path

    from drake_grasp.policy.config import SelectionConfig
    from drake_grasp.policy.scorers import USES_CNN

    scenario = config.load_scenario().name  # a scenario given as a YAML file goes by its name
    weights = config.selection.cnn_weights
    other = config.policy in USES_CNN and weights != SelectionConfig().cnn_weights
    return (f"{robot}_{scenario}_{config.policy}{'_top' if config.top_grasp else ''}"
            f"{'_' + Path(weights).stem if other else ''}.json")


def main(argv: list[str] | None = None) -> int:
    from tqdm import tqdm

    from drake_grasp.datasets.shards import JobFailure, run_jobs

    args = parse_args(argv)
    program_logging()
    try:
        table = load_table(args.config)
        base = dc.replace(table.base, robot=args.robot or table.base.robot, seed=args.seed,
                          objects=table.base.objects if args.objects is None else args.objects,
                          object_units=args.object_units or table.base.object_units)
        table = dc.replace(table, runs=args.runs or table.runs,
                           challenging_runs=args.challenging_runs or table.challenging_runs, base=base)
        table.base.check()
        robot = table.base.robot_spec()
        for objects, units in {(c.object_set(), c.object_units) for c in table.evaluations()}:
            load_object_set(objects, units)  # (a missing or unusable set is named before anything runs)
        configs = []
        for config in table.evaluations():
            make_scorer(config.policy, robot, config.selection)
            configs.append(dc.replace(config, objects=config.object_set()))
        entries = []  # per configuration: its report, its header, its seeds and the runs done
        jobs: list[tuple[int, EvaluationConfig, int]] = []  # (entry index, its configuration, a seed)
        for i, config in enumerate(configs):
            path = args.out / report_name(robot.name, config)
            if any(path == other for other, *_ in entries):
                raise ValueError(f"two entries of {args.config} would write one report, {path.name}: they "
                                 "differ only in what the report's name does not say (the stop)")
            header = report_header(config)  # (digests of the weights files: made once an entry)
            entries.append((path, header, config.seeds, finished_runs(path, header)))
            done = {r["seed"] for r in entries[-1][3]}
            jobs += [(i, config, seed) for seed in config.seeds if seed not in done]
        jobs = job_order(jobs)
    except ValueError as e:
        return fail(e)
    total = sum(len(seeds) for _, _, seeds, _ in entries)
    if args.table_only:
        if not any(path.exists() for path, *_ in entries):
            return fail(f"no report of this table in {args.out} yet: run the command without --table-only")
        print(write_table(args, robot.name, configs, argv, 0.0))
        return 0
    print(f"drake_grasp experiments: {len(configs)} entries, {total} runs ({total - len(jobs)} already done) "
          f"into {args.out}", flush=True)
    start = time.perf_counter()
    failed: list[str] = []  # the runs that raised, by report and seed
    # The entries of a scenario share each seed's dropped scene (on this machine; a Ray cluster's
    # nodes settle their own).
    settled = contextlib.nullcontext(None) if args.ray_address else tempfile.TemporaryDirectory(
        prefix="drake_grasp_settled_")
    try:
        with settled as settled_folder, sigterm_interrupts(), tqdm(
                total=total, initial=total - len(jobs), unit="runs", dynamic_ncols=True) as bar:
            workers = args.workers or os.cpu_count() or 1
            run_job = functools.partial(_run, settled_folder=settled_folder)
            results = run_jobs(run_job, jobs, workers=workers, ray_address=args.ray_address,
                               worker_init=functools.partial(simulation_worker, workers), keep_going=True)
            for (i, _, seed), run in results:
                path, header, seeds, runs = entries[i]
                if isinstance(run, JobFailure):  # one run's bug must not cost the others
                    failed.append(f"{path.name} seed {seed}")
                    bar.write(failed_run_line(f"{path.name} seed {seed}", run), file=sys.stderr)
                    continue
                runs.append(run)
                write_report(path, header, seeds, runs)
                bar.update()
    except KeyboardInterrupt:
        write_table(args, robot.name, configs, argv, time.perf_counter() - start)
        print("interrupted: finished runs are in their reports and the table; the same command goes on",
              file=sys.stderr)
        return 130
    except ValueError as e:
        return fail(e)
    print(write_table(args, robot.name, configs, argv, time.perf_counter() - start))
    if failed:
        print(f"error: {len(failed)} run(s) failed ({'; '.join(failed)}); the others are in their reports; "
              "the same command retries them", file=sys.stderr)
        return 1
    return 0


def write_table(args: argparse.Namespace, robot: str, configs: list[EvaluationConfig], argv: list[str] | None,
                wall: float) -> str:
    """table.md, summary.json and the charts of the entries' reports as they stand; returns the table."""
    from drake_grasp.evaluation.benchmark import benchmark_markdown
    from drake_grasp.evaluation.reports import (
        load_reports,
        markdown_table,
        plot_ablation,
        plot_success_and_completion,
    )

    names = {report_name(robot, c) for c in configs}
    results = [c for c in load_reports(args.out, robot=robot) if c.path.name in names]
    if not results:
        return "no finished runs yet"
    table = markdown_table(results)
    field = benchmark_markdown(results)
    if field:
        table += "\n\n## The field's clutter benchmark (rates pooled over rounds)\n\n" + field
    given = argv if argv is not None else sys.argv[1:]  # (the command that runs them: not --table-only)
    command = "python -m drake_grasp experiments " + " ".join(a for a in given if a != "--table-only")
    run_time = sum(json.loads(c.path.read_text()).get("wall_time_s", 0.0) for c in results)
    done = sum(c.num_runs for c in results)
    timing = (f"{done} runs, {run_time / 3600:.1f} h of run time (each run on one core, summed over the "
              f"sessions that made them); this invocation {wall:.0f} s")
    (args.out / "table.md").write_text(f"# Closed-loop grasping, {robot}\n\n`{command}`\n\n{timing}\n\n"
                                       f"{table}\n")
    plot_success_and_completion(results, args.out / "success_and_completion.png")
    if any(c.scenario == "ablation" for c in results):
        plot_ablation(results, args.out / "ablation.png")
    rates = ("grasp_success_rate", "completion_rate", "planning_success_rate")
    reports = [{"report": c.path.name, "scenario": c.scenario, "policy": c.policy, "top_grasp": c.top_grasp,
              "runs": c.num_runs,
              **{rate: dict(zip(("mean", "ci95"), c.rate(rate), strict=True)) for rate in rates}}
             for c in results]
    summary = {"robot": robot, "command": command, "wall_time_s": wall, "run_time_s": run_time,
               "reports": reports}
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(f"wrote {args.out}/table.md, summary.json and the charts; {timing}")
    return table


if __name__ == "__main__":
    sys.exit(main())
