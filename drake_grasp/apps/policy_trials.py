"""The policy's own first choices tried in physics, scene by scene: selection variants compared in pairs.

    python -m drake_grasp.policy_trials --objects data/objects/validation_hard --scenes 60 --seed 0 \\
        --variant default --variant cameras=cnn_weights:models/grasp_cnn_cameras.pt \\
        --out reports/policy_trials/validation_hard

Each seeded scene (`grasp_collection.build_scene`: 1 to N objects of the set in the scenario's first
cluster, settled together; the `standard` scenario by default, the closed loop's scene, up to 10 objects
within 12 cm) is observed as the closed loop observes it; every --variant ranks the same 500 candidates
and its --top choices are tried with the floating hand (`drake_grasp.policy.choice_trials`). Written:
OUT.jsonl (one line a scene; rerunning the command continues it, Ctrl-C loses only the scenes in
flight), OUT.json and OUT.md (each variant's first-choice success rate with its 95 % interval, and each
variant paired with the first: where their first choices differ, the scenes each alone lifted, with a
sign test).
Choose models and options on validation objects only, and a default on the standard scene: piles
(`--scenario pile`) once favoured a change that the standard scene and the closed loop both rejected.
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
from pathlib import Path

from drake_grasp.apps.cli import (
    fail,
    header_fields,
    out_file,
    positive_int,
    quiet_drake,
    use_threads,
    write_report_pair,
)
from drake_grasp.policy.choice_trials import (
    DEFAULT_VARIANT,
    parse_variant,
    scene_choices,
    summarize,
    summary_markdown,
)


def _variant(text: str):
    try:
        return parse_variant(text)
    except (ValueError, TypeError) as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    from drake_grasp.policy.scorers import POLICIES
    from drake_grasp.robots import ROBOTS

    parser = argparse.ArgumentParser(prog="python -m drake_grasp.policy_trials", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--objects", required=True, help="object set (a shipped name or a folder)")
    parser.add_argument("--scenario", default="standard",
                        help="scenario name or YAML (default standard, the closed loop's scene; pile: 1 to 6 "
                             "objects within 6 cm)")
    parser.add_argument("--scenes", type=positive_int, default=50, help="seeded scenes (default 50)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--variant", type=_variant, action="append", default=None,
                        metavar="NAME[=FIELD:VALUE,...]",
                        help="a selection to compare (SelectionConfig fields: cnn_weights, hold_weights, "
                             "finger_symmetry, staged, ...); repeat it; the first is the baseline "
                             "(default: one variant, 'default')")
    parser.add_argument("--top", type=positive_int, default=1, help="choices tried per variant (default 1)")
    parser.add_argument("--policy", default="cnn_rp", help=f"one of {sorted(POLICIES)} (default cnn_rp)")
    parser.add_argument("--robot", default="panda",
                        help=f"whose p_r ranks: one of {sorted(ROBOTS)} or an arm YAML file (default panda)")
    parser.add_argument("--depth-noise", action="store_true", help="the camera with its noise model")
    parser.add_argument("--workers", type=positive_int, default=None, help="default: one per core")
    parser.add_argument("--out", type=out_file, required=True,
                        help="OUT.jsonl, OUT.json and OUT.md are written")
    return parser.parse_args(argv)


def _worker_init() -> None:
    """One torch thread a worker: the workers already use every core."""
    quiet_drake()
    use_threads(1)


def _read_done(path: Path, job: dict) -> dict[int, dict]:
    """The scenes already in OUT.jsonl (its first line is the job, which must be this one)."""
    if not path.exists():
        return {}
    lines = path.read_text().splitlines()
    header = json.loads(lines[0]) if lines else {}
    if header.get("job") != job:
        raise ValueError(f"{path} holds another job ({header.get('job')}); choose another --out or delete it")
    done = {}
    for line in lines[1:]:
        try:
            record = json.loads(line)
        except json.JSONDecodeError:  # a line cut short by an interruption: that scene runs again
            continue
        done[record["scene"]] = record
    return done


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    quiet_drake()
    variants = args.variant or [parse_variant(DEFAULT_VARIANT)]
    if len({v.name for v in variants}) != len(variants):
        return fail("--variant names must differ")
    job = {"objects": args.objects, "scenario": args.scenario, "seed": args.seed, "top": args.top,
           "policy": args.policy, "robot": args.robot, "depth_noise": args.depth_noise,
           "variants": {v.name: header_fields(v.selection, added_later={"hold_join_parts": False})
                        for v in variants}}
    out_lines = args.out.with_name(args.out.name + ".jsonl")
    try:
        from drake_grasp.policy.scorers import make_scorer
        from drake_grasp.robots import get_robot
        from drake_grasp.simulation.objects import load_object_set
        from drake_grasp.simulation.scenario import load_scenario

        load_scenario(args.scenario)
        load_object_set(args.objects)
        for v in variants:  # (unknown policies, robots and missing weights fail here, before any physics)
            make_scorer(args.policy, get_robot(args.robot), v.selection)
        done = _read_done(out_lines, job)
    except (ValueError, FileNotFoundError, RuntimeError) as e:
        return fail(e)
    pending = [s for s in range(args.scenes) if s not in done]
    if done:
        print(f"resuming: {len(done)} of {args.scenes} scenes already in {out_lines}", file=sys.stderr)
    if not out_lines.exists():
        out_lines.parent.mkdir(parents=True, exist_ok=True)
        out_lines.write_text(json.dumps({"job": job}) + "\n")
    fn = functools.partial(scene_choices, objects=args.objects, scenario=args.scenario, seed=args.seed,
                           variants=variants, top=args.top, policy=args.policy, robot=args.robot,
                           depth_noise=args.depth_noise)
    from tqdm import tqdm

    from drake_grasp.datasets.shards import run_jobs

    try:
        with tqdm(total=args.scenes, initial=len(done), unit="scenes", dynamic_ncols=True) as bar, \
                out_lines.open("a") as sink:
            jobs = run_jobs(fn, pending, workers=args.workers or 0, worker_init=_worker_init)
            for scene_id, record in jobs:
                done[scene_id] = record
                sink.write(json.dumps(record) + "\n")
                sink.flush()
                bar.update()
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished scenes are kept in {out_lines}; rerun the command to continue",
              file=sys.stderr)
        return 130
    except RuntimeError as e:
        return fail(e)
    records = [done[s] for s in sorted(done) if s < args.scenes]
    summary = summarize(records, [v.name for v in variants])
    write_report_pair(args.out, {"job": job, **summary}, summary_markdown(summary, job))
    return 0


if __name__ == "__main__":
    sys.exit(main())
