"""The paper's experiments in one command: every (scenario x policy) cell, N runs each, tables and charts.

    python -m drake_grasp.experiments --robot panda --runs 30 --out reports/experiments

Cells: by default the paper's (Fig. 7: RAND, GPD1c, GPD, VPG and the paper's policy in the
standard and challenging scenes; Table I: RAND, RP only, 3DCNN and the paper's policy in the
ablation scene), with --policies each of --scenarios with each policy; plus the "top
grasping" variant (candidates straight down only) of each policy in the standard scene
(VPG's grasps are straight down already: it has no separate variant). Every cell is
a `simulate` report (OUT/ROBOT_SCENARIO_POLICY[_top].json) written after every run,
so the whole table resumes where it stopped; the runs of all cells share one pool of
worker processes (one per core) or a Ray cluster (--ray-address), with one progress
bar, seed by seed (a table cut short has runs in every cell). At the end:
OUT/table.md (every rate as mean +- 95 % CI over runs, the paper's number beside ours
where it gives one), OUT/summary.json (the same, this invocation's wall time and the
run time of every run summed over the sessions that made them),
OUT/success_and_completion.png (paper Fig. 7) and OUT/ablation.png (Table I), also
on Ctrl-C (of the runs finished so far); --table-only writes them and runs nothing.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from drake_grasp.apps.cli import (
    add_selection_option,
    fail,
    non_negative_int,
    out_file,
    positive_int,
    quiet_drake,
    selection_config,
)
from drake_grasp.apps.simulate import RunSpec, cell_config, finished_runs, run_one, write_report
from drake_grasp.policy.scorers import POLICIES, make_scorer
from drake_grasp.robots import get_robot

DEFAULT_SCENARIOS = ("standard", "challenging", "ablation")
# The paper's cells: Fig. 7 compares the baselines in the standard and challenging scenes, Table I
# ablates the reachability predictor in the ablation scene.
PAPER_POLICIES = {"standard": ("rand", "gpd1c", "gpd", "vpg", "cnn_rp"),
                  "challenging": ("rand", "gpd1c", "gpd", "vpg", "cnn_rp"),
                  "ablation": ("rand", "rp", "cnn", "cnn_rp")}
ALWAYS_TOP_DOWN = ("vpg",)  # policies whose grasps are straight down already (no top-grasp variant)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp.experiments", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="panda", help="a built-in arm or an arm YAML file (default panda)")
    parser.add_argument("--runs", type=positive_int, default=30, help="runs a cell (default 30)")
    parser.add_argument("--challenging-runs", type=positive_int, default=None,
                        help="runs per challenging cell (default --runs; the scene is slow)")
    parser.add_argument("--scenarios", default=",".join(DEFAULT_SCENARIOS))
    parser.add_argument("--policies", default=None,
                        help=f"comma-separated, of {sorted(POLICIES)}, run in every scenario "
                             "(default: the paper's policies of each scenario)")
    parser.add_argument("--no-top-grasp", action="store_true", help="leave out the top-grasping variants")
    parser.add_argument("--seed", type=non_negative_int, default=0, help="run k of every cell uses seed + k")
    parser.add_argument("--workers", type=positive_int, default=None, help="default: one per core")
    parser.add_argument("--ray-address", default=None, help="run on a Ray cluster ('auto', 'ray://host:10001')")
    parser.add_argument("--table-only", action="store_true",
                        help="run nothing: write the table and charts of the reports in --out as they stand")
    parser.add_argument("--out", type=out_file, required=True)
    add_selection_option(parser)  # the CNN policies' cells (the default models unless given)
    return parser.parse_args(argv)


def _run(job: tuple[int, RunSpec, int]) -> dict:
    quiet_drake()
    _, spec, seed = job
    return run_one(spec, seed)


def report_name(robot: str, spec: RunSpec) -> str:
    scenario = spec.load_scenario().name  # a scenario given as a YAML file goes by its name
    return f"{robot}_{scenario}_{spec.policy}{'_top' if spec.top_grasp else ''}.json"


def cells_to_run(scenarios: list[str], policies: str | None, top_grasp: bool) -> list[tuple[str, str, bool]]:
    """(policy, scenario, top grasp) of every cell, policy by policy: the paper's policies of each
    scenario, or each of the comma-separated `policies` in every scenario; then the top-grasp variants."""
    from drake_grasp.simulation.scenario import load_scenario

    chosen = None if policies is None else [p.strip() for p in policies.split(",") if p.strip()]
    names = {scenario: load_scenario(scenario).name for scenario in scenarios}  # (a YAML file: its name)
    per_scenario = {scenario: chosen if chosen is not None else PAPER_POLICIES.get(names[scenario], ())
                    for scenario in scenarios}
    if not any(per_scenario.values()):
        raise ValueError(f"no policies for the scenarios {', '.join(scenarios)}: name them with --policies")
    order = list(dict.fromkeys(p for s in scenarios for p in per_scenario[s]))
    cells = [(policy, scenario, False) for policy in order for scenario in scenarios
             if policy in per_scenario[scenario]]
    standard = [s for s in scenarios if names[s] == "standard"]
    if top_grasp and standard:
        cells += [(policy, standard[0], True) for policy in per_scenario[standard[0]]
                  if policy not in ALWAYS_TOP_DOWN]
    return cells


def main(argv: list[str] | None = None) -> int:
    from tqdm import tqdm

    from drake_grasp.datasets.shards import run_jobs

    args = parse_args(argv)
    quiet_drake()
    scenarios = [s.strip() for s in args.scenarios.split(",") if s.strip()]
    try:
        robot = get_robot(args.robot)
        specs = []
        selection = selection_config(args)
        for policy, scenario, top_grasp in cells_to_run(scenarios, args.policies, not args.no_top_grasp):
            make_scorer(policy, robot, selection)
            cell = cell_config(robot.source, policy, paper_loop=False, transit_ignores_objects=False)
            specs.append(RunSpec(robot.source, scenario, policy, None, cell, top_grasp=top_grasp,
                                 selection=selection))
        cells = []  # per spec: its report, its header, its seeds and the runs done
        jobs: list[tuple[int, RunSpec, int]] = []  # (cell index, its spec, a seed)
        for i, spec in enumerate(specs):
            slow = spec.scenario == "challenging" and args.challenging_runs
            seeds = [args.seed + k for k in range(args.challenging_runs if slow else args.runs)]
            path = args.out / report_name(robot.name, spec)
            header = spec.header(robot.name)  # (digests of the weights files: made once a cell)
            cells.append((path, header, seeds, finished_runs(path, header)))
            done = {r["seed"] for r in cells[-1][3]}
            pending = [seed for seed in seeds if seed not in done]
            jobs += [(i, spec, seed) for seed in pending]
        jobs.sort(key=lambda job: (job[2], job[0]))  # seed by seed: a table cut short has runs in every cell
    except ValueError as e:
        return fail(e)
    total = sum(len(seeds) for _, _, seeds, _ in cells)
    if args.table_only:
        print(write_table(args, robot.name, specs, argv, 0.0))
        return 0
    print(f"drake_grasp.experiments: {len(specs)} cells, {total} runs ({total - len(jobs)} already done) "
          f"into {args.out}", flush=True)
    start = time.perf_counter()
    try:
        with tqdm(total=total, initial=total - len(jobs), unit="runs", dynamic_ncols=True) as bar:
            results = run_jobs(_run, jobs, workers=args.workers or 0, ray_address=args.ray_address,
                               worker_init=quiet_drake)
            for (i, _, _), run in results:
                path, header, seeds, runs = cells[i]
                runs.append(run)
                write_report(path, header, seeds, runs)
                bar.update()
    except KeyboardInterrupt:
        write_table(args, robot.name, specs, argv, time.perf_counter() - start)
        print("interrupted: finished runs are in their reports and the table; the same command goes on",
              file=sys.stderr)
        return 130
    except ValueError as e:
        return fail(e)
    print(write_table(args, robot.name, specs, argv, time.perf_counter() - start))
    return 0


def write_table(args: argparse.Namespace, robot: str, specs: list[RunSpec], argv: list[str] | None,
                wall: float) -> str:
    """table.md, summary.json and the charts of the cells' reports as they stand; returns the table."""
    from drake_grasp.results import load_reports, markdown_table, plot_ablation, plot_success_and_completion

    names = {report_name(robot, s) for s in specs}
    results = [c for c in load_reports(args.out, robot=robot) if c.path.name in names]
    if not results:
        return "no finished runs yet"
    table = markdown_table(results)
    given = argv if argv is not None else sys.argv[1:]  # (the command that runs them: not --table-only)
    command = "python -m drake_grasp.experiments " + " ".join(a for a in given if a != "--table-only")
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
    cells = [{"report": c.path.name, "scenario": c.scenario, "policy": c.policy, "top_grasp": c.top_grasp,
              "runs": c.num_runs,
              **{rate: dict(zip(("mean", "ci95"), c.rate(rate), strict=True)) for rate in rates}}
             for c in results]
    summary = {"robot": robot, "command": command, "wall_time_s": wall, "run_time_s": run_time,
               "cells": cells}
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(f"wrote {args.out}/table.md, summary.json and the charts; {timing}")
    return table


if __name__ == "__main__":
    sys.exit(main())
