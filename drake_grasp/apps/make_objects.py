"""A procedural object set: N graspable objects, deterministic from the seed, as SDF files.

    python -m drake_grasp make_objects --count 500 --seed 0 --out data/objects/train

    python -m drake_grasp make_objects --count 300 --seed 3 --elongate 1.3 2.0 --out data/objects/train_long

Object k is a pure function of (seed, k, --families, --elongate) (see
`drake_grasp.simulation.object_generation` for the families, sizes, masses and friction).
Each becomes `NAME.sdf` with its convex pieces (concave meshes decomposed by CoACD) as OBJ
files in `meshes/`; `manifest.json` lists them. The folder is an object set for every
`--objects` option. Objects already written are kept, so an interrupted run continues;
worker processes share the work.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys
from pathlib import Path

from drake_grasp.apps.cli import fail, non_negative_int, out_folder, positive_int
from drake_grasp.datasets.shards import run_jobs
from drake_grasp.simulation.object_generation import (
    EXTRA_FAMILIES,
    FAMILIES,
    GENERATOR_VERSION,
    HOUSEHOLD_FAMILIES,
    MAX_ELONGATION,
)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp make_objects", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--count", type=positive_int, required=True, help="objects to make")
    parser.add_argument("--seed", type=non_negative_int, default=0)
    parser.add_argument("--out", type=out_folder, required=True, help="the object set's folder")
    parser.add_argument("--families", default=",".join(FAMILIES),
                        help=f"comma-separated families (default all: {','.join(FAMILIES)}; also on "
                             f"request: {','.join(EXTRA_FAMILIES)}, and the household objects at their real "
                             f"sizes, 'household' for all of them: {','.join(HOUSEHOLD_FAMILIES)})")
    parser.add_argument("--elongate", type=float, nargs=2, metavar=("LOW", "HIGH"), default=None,
                        help="stretch each object along its longest extent by a factor drawn from "
                             "[LOW, HIGH] (for example 1.3 2.0: objects up to about 30 cm)")
    parser.add_argument("--workers", type=positive_int, default=None, help="default: one per core")
    return parser.parse_args(argv)


def make_one(seed: int, k: int, *, families: tuple[str, ...], elongation: tuple[float, float] | None,
             out: str) -> dict:
    from drake_grasp.simulation.object_generation import generate_object, write_sdf

    obj = generate_object(seed, k, families, elongation)
    write_sdf(obj, Path(out))
    return {"index": k, "name": obj.name, "family": obj.family, "pieces": len(obj.pieces),
            "mass": round(obj.mass, 4), "friction": round(obj.friction, 3),
            "extents": [round(float(x), 4) for x in obj.extents()]}


def main(argv: list[str] | None = None) -> int:
    from tqdm import tqdm

    args = parse_args(argv)
    names = [f.strip() for f in args.families.split(",") if f.strip()]
    families = tuple(f for name in names for f in (HOUSEHOLD_FAMILIES if name == "household" else [name]))
    unknown = sorted(set(families) - set(FAMILIES) - set(EXTRA_FAMILIES) - set(HOUSEHOLD_FAMILIES))
    if unknown or not families:
        known = ", ".join(FAMILIES + EXTRA_FAMILIES + HOUSEHOLD_FAMILIES + ("household",))
        return fail(f"unknown object families {unknown}; choose from: {known}")
    elongation = None if args.elongate is None else tuple(args.elongate)
    if elongation is not None and not 1.0 <= elongation[0] <= elongation[1] <= MAX_ELONGATION:
        return fail(f"--elongate needs 1 <= LOW <= HIGH <= {MAX_ELONGATION}, got {args.elongate}")
    args.out.mkdir(parents=True, exist_ok=True)
    manifest_path = args.out / "manifest.json"
    job = {"kind": "objects", "seed": args.seed, "families": list(families), "generator": GENERATOR_VERSION}
    if elongation is not None:  # (a plain corpus's manifest has no such entry)
        job["elongation"] = list(elongation)
    entries: dict[int, dict] = {}
    if manifest_path.exists():
        old = json.loads(manifest_path.read_text())
        if {k: old.get(k) for k in {*job, "elongation"}} != {"elongation": None, **job}:
            return fail(f"{args.out} holds another object set (seed, families, elongation or generator "
                        f"version differ); use another --out or remove it")
        entries = {e["index"]: e for e in old["objects"] if (args.out / f"{e['name']}.sdf").exists()}
    pending = [k for k in range(args.count) if k not in entries]
    workers = min(args.workers or os.cpu_count() or 1, max(1, len(pending)))

    def save() -> None:
        objects = [entries[k] for k in sorted(entries)]
        manifest_path.write_text(json.dumps({**job, "count": len(objects), "objects": objects}, indent=1))

    try:
        with tqdm(total=args.count, initial=args.count - len(pending), unit="objects") as bar:
            make = functools.partial(make_one, args.seed, families=families, elongation=elongation,
                                     out=str(args.out))
            results = run_jobs(make, pending, workers=workers)
            for _, entry in results:
                entries[entry["index"]] = entry
                bar.update()
                if len(entries) % 20 == 0:
                    save()
    except KeyboardInterrupt:
        print(f"interrupted: {len(entries)} of {args.count} objects kept; rerun to continue", file=sys.stderr)
        return 130
    finally:  # every object written so far is listed, whatever stopped the run
        save()
    print(f"{len(entries)} objects in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
