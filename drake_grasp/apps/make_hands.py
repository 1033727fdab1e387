"""A family of parallel-jaw hands: N hand files with their models, deterministic from the seed.

    python -m drake_grasp make_hands --count 6 --seed 0 --out data/hands/train

Hand k is a palm box and two coupled prismatic finger pads whose sizes are drawn from
(seed, k): strokes 5-14 cm, fingers 3.5-8 cm long, pads 1-3 cm wide, palms 4.5-9 cm deep; with
`--wide` also palms 4-9 cm wide, fingers up to 3.5 cm thick and grasp depths of 0.5-2 cm
(`drake_grasp.robot.parallel_jaw`). Each becomes `NAME.sdf` and `NAME.yaml`, a hand file for
every `--hand` option (trials of many hands for a hand-conditioned CNN, docs/your_hand.md).
"""

from __future__ import annotations

import argparse
import sys

from drake_grasp.apps.cli import non_negative_int, out_folder, positive_int


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp make_hands", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--count", type=positive_int, required=True, help="hands to make")
    parser.add_argument("--seed", type=non_negative_int, default=0)
    parser.add_argument("--out", type=out_folder, required=True, help="the hands' folder")
    parser.add_argument("--wide", action="store_true",
                        help="the wide family: also palms 4-9 cm wide, fingers up to 3.5 cm thick, grasp "
                             "depths of 0.5-2 cm")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    from drake_grasp.robot.hand import get_hand
    from drake_grasp.robot.parallel_jaw import random_hand, write_hand

    args = parse_args(argv)
    for k in range(args.count):
        hand = get_hand(str(write_hand(random_hand(args.seed, k, args.wide), args.out)))
        print(f"{hand.name}: stroke {hand.stroke * 1000:.0f} mm, fingers {hand.finger_length * 1000:.0f} mm, "
              f"pads {hand.finger_size[0] * 1000:.0f} x {hand.finger_size[1] * 1000:.0f} mm, "
              f"palm {hand.palm_depth * 1000:.0f} mm deep")
    print(f"{args.count} hand files in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
