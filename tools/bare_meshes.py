"""Writes a folder of bare OBJ meshes, as a download would give them.

    python tools/bare_meshes.py --count 12 --seed 7 --out /tmp/bare_meshes

Each is a procedural object (`make_objects`' generator, a seed of its own) written as one triangle
soup (its pieces' surfaces in one file, as many downloaded meshes are): no pieces, no mass, no Drake
tags. A folder of them is what `--objects` decomposes on first use (README, "Your objects").
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import trimesh

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drake_grasp.simulation.object_generation import generate_object  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--count", type=int, default=12)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for k in range(args.count):
        obj = generate_object(args.seed, k)
        whole = trimesh.util.concatenate([piece.trimesh() for piece in obj.pieces])
        whole.export(args.out / f"{obj.family}_{k:02d}.obj")
    print(f"{args.count} bare OBJ meshes in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
