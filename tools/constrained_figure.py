"""What the cell sees of the constrained scene: both depth images and the planning world, as one PNG.

    python tools/constrained_figure.py --seed 40 --out docs/constrained.png

Builds the `constrained` scene for a seed, lets it settle, and draws the camera above and the camera
from the side (depth), the cloud from above split into objects and scene structure, and a section
through the planning world's columns at the objects (the seat a board over free space).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drake_grasp.cell.diagram import build_cell  # noqa: E402
from drake_grasp.planning.obstacles import (  # noqa: E402
    ObservedScene,
    ObstacleConfig,
    free_voxels,
    obstacle_columns,
)
from drake_grasp.policy.scorers import random_scorer  # noqa: E402
from drake_grasp.robot.specs import ROBOTS  # noqa: E402
from drake_grasp.simulation.objects import load_object_set  # noqa: E402
from drake_grasp.simulation.scenario import load_scenario  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=40)
    parser.add_argument("--out", type=Path, default=Path("docs/constrained.png"))
    args = parser.parse_args()
    from matplotlib.figure import Figure

    scenario = load_scenario("constrained")
    cell = build_cell(robot=ROBOTS["panda"], scenario=scenario, scorer=random_scorer,
                      object_models=load_object_set(scenario.object_set), seed=args.seed)
    cell.advance(scenario.settle_time)
    station_context = cell.station.GetMyContextFromRoot(cell.context)
    depth_above = cell.station.GetOutputPort("depth_image").Eval(station_context).data.squeeze()
    side = cell.station.GetSubsystemByName("camera_1")
    side_context = side.GetMyContextFromRoot(cell.context)
    depth_side = side.depth_image_32F_output_port().Eval(side_context).data.squeeze()
    perception_context = cell.perception.GetMyContextFromRoot(cell.context)
    cloud = cell.perception.GetOutputPort("object_cloud").Eval(perception_context)

    config = ObstacleConfig()
    scene = ObservedScene(cloud.points, cloud.structure, cloud.rays)
    free = free_voxels(cloud.rays, config, 0.0, float(cloud.structure[:, 2].max()) + config.slice)
    far = np.eye(4)
    far[:3, 3] = [2.0, 2.0, 0.0]  # a grasp elsewhere: no corridor cuts the section
    columns = obstacle_columns(scene, far, config, free=free)
    y_section = float(np.median(cloud.points[:, 1]))
    row = np.abs(columns[:, 1] - y_section) < config.cell / 2

    fig = Figure(figsize=(13, 3.6), dpi=100)
    axes = fig.subplots(1, 4)
    # Depth ranges [m], nearer darker: the table top 1.3 m under the camera above; the stool 0.5-1 m
    # in front of the camera from the side.
    for ax, image, title, (near, far) in ((axes[0], depth_above, "camera above (depth)", (0.9, 1.35)),
                                          (axes[1], depth_side, "camera from the side (depth)", (0.4, 1.2))):
        ax.imshow(image, cmap="gray", vmin=near, vmax=far)
        ax.set_title(title, fontsize=9)
        ax.set_axis_off()
    ax = axes[2]
    ax.plot(cloud.structure[::7, 0], cloud.structure[::7, 1], ",", color="0.5")
    ax.plot(cloud.points[::3, 0], cloud.points[::3, 1], ".", ms=1, color="tab:orange")
    ax.set_title("cloud from above: objects (orange), structure (grey)", fontsize=9)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax = axes[3]
    for x, _, bottom, top in columns[row]:
        bottom = max(bottom, 0.0)
        ax.add_patch(_box(x - config.cell / 2, bottom, config.cell, max(top - bottom, 0.005)))
    ax.set_xlim(0.3, 0.9)
    ax.set_ylim(0.0, 0.35)
    ax.set_aspect("equal")
    ax.set_title(f"planning columns at y = {y_section:.2f} m", fontsize=9)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out)
    print(f"wrote {args.out}")
    return 0


def _box(x: float, z: float, width: float, height: float):
    from matplotlib.patches import Rectangle

    return Rectangle((x, z), width, height, facecolor="tab:blue", edgecolor="white", lw=0.5)


if __name__ == "__main__":
    raise SystemExit(main())
