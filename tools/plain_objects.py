"""Copies an object set without its Drake contact tags, as a Gazebo or ROS user's files would come.

    python tools/plain_objects.py primitives /tmp/plain_primitives

Every `<drake:proximity_properties>` element is dropped and the meshes are copied beside the
models, so the copy holds the same shapes, masses and inertias with no contact model of its own:
`simulate --objects /tmp/plain_primitives` measures what the project's filled-in contact model
gives such files (README, "Your objects").
"""

from __future__ import annotations

import argparse
import re
import shutil
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drake_grasp.robot.paths import OBJECT_SETS_DIR  # noqa: E402

DRAKE_TAGS = re.compile(r"<drake:proximity_properties>.*?</drake:proximity_properties>", re.S)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("object_set", help="a shipped set's name or a folder")
    parser.add_argument("out", type=Path)
    args = parser.parse_args()
    source = OBJECT_SETS_DIR / args.object_set if "/" not in args.object_set else Path(args.object_set)
    if not source.is_dir():
        print(f"error: no object set {args.object_set}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    for path in sorted(source.iterdir()):
        if path.suffix == ".sdf":
            (args.out / path.name).write_text(DRAKE_TAGS.sub("", path.read_text()))
        elif path.is_file():
            shutil.copy(path, args.out / path.name)
        elif path.is_dir():
            shutil.copytree(path, args.out / path.name, dirs_exist_ok=True)
    print(f"{args.out}: {args.object_set} without Drake contact tags")
    return 0


if __name__ == "__main__":
    sys.exit(main())
