"""A noisy-camera grasp job's scenes seen again through a perfect camera: the same trials, noise-free clouds.

    python -m drake_grasp.rerender_grasps --source data/grasps/validation --out data/grasps/validation_perfect

Each scene of the `collect_grasps --depth-noise` job in --source is rebuilt from its seed, settled
again and observed without depth noise (`drake_grasp.datasets.rerender`); its trials are copied with
their outcomes. A scene whose objects did not settle where they did (the noise-free cloud farther than
6 mm from the stored one, 95th percentile) is left out with its trials. Shard k of --out is shard k of
--source: rerunning continues, Ctrl-C loses only the shards in flight. The output is a collect_grasps
folder (`evaluate_cnn`, `train` read it); paired with its source it tells what the camera alone changes.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from drake_grasp.apps.cli import collect_shards, fail, out_folder, positive_int, quiet_drake, shard_range
from drake_grasp.datasets.grasp_data import load_grasp_dataset
from drake_grasp.datasets.rerender import perfect_camera_manifest, read_source_manifest, rerender_shard
from drake_grasp.datasets.shards import shard_files, shard_index, write_manifest


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp.rerender_grasps", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--source", type=Path, required=True, help="a collect_grasps --depth-noise folder")
    parser.add_argument("--out", type=out_folder, required=True, help="folder of the re-rendered shards")
    parser.add_argument("--workers", type=positive_int, default=None, help="default: one per core")
    parser.add_argument("--shards", type=shard_range, default=None, metavar="FIRST:STOP",
                        help="only these shards of the source")
    args = parser.parse_args(argv)
    quiet_drake()
    try:
        manifest = read_source_manifest(args.source)
        files = shard_files(args.source)
        if not files:
            raise ValueError(f"no data shards in {args.source}")
        num_shards = shard_index(files[-1]) + 1
        if len(files) != num_shards:
            raise ValueError(f"{args.source} lacks shards (it has {len(files)} of 0-{num_shards - 1}); "
                             "finish its collection first")
        write_manifest(args.out, perfect_camera_manifest(manifest, args.source), size_key="scenes")
    except ValueError as e:
        return fail(e)
    args.ray_address = None
    job = {"source": str(args.source)}
    code = collect_shards(rerender_shard, job, out_dir=args.out, num_shards=num_shards,
                          shard_size=manifest["scenes_per_shard"] * manifest["per_scene"], unit="trials",
                          args=args)
    if code == 0 and len(shard_files(args.out)) == num_shards:
        source, out = load_grasp_dataset(args.source), load_grasp_dataset(args.out)
        print(f"{len(out.clouds)} of {len(source.clouds)} scenes settled as before and were kept "
              f"({len(out)} of {len(source)} trials)")
    return code


if __name__ == "__main__":
    sys.exit(main())
