"""One grasp attempt of the closed loop, recorded as a self-contained Meshcat HTML page.

Builds the cell for one seeded scene, draws the policy's candidates coloured by
p_g (p_r * p_s), lets the executive plan and execute its first attempt in physics
with Meshcat recording, and writes Meshcat's static HTML: open it in any browser
(no install, no server) and play the animation from the "Animations" controls.
With --screenshot, a headless Chromium opens the page, saves what it draws as a
PNG, and the program checks that the picture shows the scene (the table and the
coloured objects, not an empty background).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
from pathlib import Path

import numpy as np

from drake_grasp.apps.cli import fail, non_negative_int, out_file, quiet_drake
from drake_grasp.policy.scorers import POLICIES, make_scorer, policy_scenario
from drake_grasp.robot.arms import get_robot
from drake_grasp.robot.specs import ROBOTS
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.scenario import load_scenario


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp record_grasp", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="panda",
                        help=f"one of {sorted(ROBOTS)} or an arm YAML file (default panda)")
    parser.add_argument("--scenario", default="standard", help="scenario name or YAML (default standard)")
    parser.add_argument("--objects", default=None, help="object set (default: the scenario's)")
    parser.add_argument("--policy", default="cnn_rp", help=f"one of {sorted(POLICIES)} (default cnn_rp)")
    parser.add_argument("--seed", type=non_negative_int, default=0)
    parser.add_argument("--out", type=out_file, default=None,
                        help="the HTML page to write (default reports/grasp_POLICY.html)")
    parser.add_argument("--screenshot", type=Path, default=None,
                        help="also open the page in headless Chromium, save its picture here and check it")
    return parser.parse_args(argv)


CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome")
p_WCamera = [1.15, -0.75, 0.6]  # where the page's camera starts, looking at p_WTarget [m]
p_WTarget = [0.5, 0.0, 0.05]
MIN_SCENE_FRACTION = 0.02  # an empty page (background and grid only) has none


def find_chromium() -> str | None:
    return next((path for name in CHROMIUM_NAMES if (path := shutil.which(name))), None)


# Software WebGL takes a minute or two when the machine is busy; a headless Chromium now and then hangs
# (seen once in ten minutes on an idle machine, where it took under two the next time): a fresh one
# gets another try.
SCREENSHOT_TIMEOUT_S = 300
SCREENSHOT_TRIES = 2


def screenshot_html(html: Path, png: Path, *, size: tuple[int, int] = (1200, 900),
                    virtual_time_ms: int = 15_000) -> Path:
    """What a headless Chromium draws for the page (software WebGL), as a PNG, after `virtual_time_ms` of
    the page's time."""
    chromium = find_chromium()
    if chromium is None:
        raise FileNotFoundError("no Chromium found (Debian: apt-get install chromium)")
    png.parent.mkdir(parents=True, exist_ok=True)
    command = [chromium, "--headless=new", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
               "--use-angle=swiftshader", f"--window-size={size[0]},{size[1]}",
               f"--virtual-time-budget={virtual_time_ms}", f"--screenshot={png.resolve()}",
               html.resolve().as_uri()]
    for attempt in range(1, SCREENSHOT_TRIES + 1):
        try:
            subprocess.run(command, capture_output=True, timeout=SCREENSHOT_TIMEOUT_S, check=True)
            break
        except subprocess.TimeoutExpired:
            if attempt == SCREENSHOT_TRIES:
                raise  # (else a Chromium that hung: a fresh one)
    return png


def drawn_scene_fraction(png: Path) -> float:
    """The fraction of the picture in saturated colour: the table and objects (Meshcat's background,
    grid and the arm are grey)."""
    from PIL import Image

    hsv = np.asarray(Image.open(png).convert("RGB").convert("HSV"), dtype=float) / 255.0
    return float(np.mean((hsv[..., 1] > 0.3) & (hsv[..., 2] > 0.15)))


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    args.out = args.out or Path(f"reports/grasp_{args.policy}.html")
    quiet_drake()
    try:
        robot = get_robot(args.robot)
        scorer = make_scorer(args.policy, robot)
        scenario = policy_scenario(args.policy, load_scenario(args.scenario))
        models = load_object_set(args.objects or scenario.object_set)
    except ValueError as e:
        return fail(e)
    from pydrake.geometry import StartMeshcat

    from drake_grasp.cell.diagram import build_cell, run_attempt
    from drake_grasp.policy.drawing import draw_scored_candidates

    meshcat = StartMeshcat()
    meshcat.SetCameraPose(p_WCamera, p_WTarget)
    cell = build_cell(robot=robot, scenario=scenario, scorer=scorer, object_models=models, seed=args.seed,
                      meshcat=meshcat)
    cell.advance_to_next_look()
    ranked = cell.ranked_grasps()
    draw_scored_candidates(meshcat, "candidates", ranked.X_WG[:100], ranked.scores[:100])
    task = run_attempt(cell, record=True)
    attempt = task.attempt
    if attempt is None:
        return fail(f"the executive made no attempt: {task.mode.value}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(meshcat.StaticHtml())
    outcome = "success" if attempt.success else attempt.failure
    name = "no object" if attempt.object_index is None else cell.objects[attempt.object_index].name
    print(f"{outcome}: {name} rose {100 * attempt.rise:.1f} cm (approach {attempt.approach_angle_deg:.0f} "
          f"deg from straight down, grasp point {attempt.grasp_point}); wrote {args.out} "
          f"({args.out.stat().st_size / 1e6:.1f} MB)")
    if args.screenshot is not None:
        try:
            screenshot_html(args.out, args.screenshot)
        except (FileNotFoundError, subprocess.SubprocessError) as e:
            return fail(f"could not take the screenshot: {e}")
        fraction = drawn_scene_fraction(args.screenshot)
        print(f"screenshot {args.screenshot}: {fraction:.1%} of the picture shows the table and objects")
        if fraction < MIN_SCENE_FRACTION:
            return fail(f"the page draws no scene in headless Chromium ({fraction:.2%} in colour)")
    return 0
