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
import contextlib
import os
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from drake_grasp.apps.cli import add_hand_option, fail, non_negative_int, out_file, program_logging
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
    add_hand_option(parser)
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


# A headless Chromium draws the page (software WebGL) and writes the picture within seconds of loading
# it, but may then take minutes to shut down: it is stopped once it has said that the file is written.
# No --virtual-time-budget: waiting on the page's own clock takes from 4 s to over 5 minutes. One that
# hangs before writing gets a fresh try.
SCREENSHOT_TIMEOUT_S = 120
SCREENSHOT_TRIES = 2
SCREENSHOT_POLL_S = 0.2
SCREENSHOT_WRITTEN = b"bytes written to file"


def screenshot_html(html: Path, png: Path, *, size: tuple[int, int] = (1200, 900)) -> Path:
    """What a headless Chromium draws for the page once it has loaded, as a PNG. Raises
    subprocess.TimeoutExpired if no picture comes within SCREENSHOT_TIMEOUT_S (each of SCREENSHOT_TRIES)
    and subprocess.CalledProcessError if Chromium exits without one."""
    chromium = find_chromium()
    if chromium is None:
        raise FileNotFoundError("no Chromium found (Debian: apt-get install chromium)")
    png.parent.mkdir(parents=True, exist_ok=True)
    png.unlink(missing_ok=True)
    for attempt in range(1, SCREENSHOT_TRIES + 1):
        try:
            _take_screenshot(chromium, html, png, size)
            break
        except subprocess.TimeoutExpired:
            if attempt == SCREENSHOT_TRIES:
                raise
    return png


def _take_screenshot(chromium: str, html: Path, png: Path, size: tuple[int, int]) -> None:
    """One Chromium with a fresh profile, stopped as soon as the picture is written."""
    with tempfile.TemporaryDirectory() as folder:
        command = [chromium, "--headless=new", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
                   "--use-angle=swiftshader", f"--user-data-dir={folder}/profile",
                   f"--window-size={size[0]},{size[1]}", f"--screenshot={png.resolve()}",
                   html.resolve().as_uri()]
        log = Path(folder) / "chromium.log"
        with log.open("ab") as output:
            process = subprocess.Popen(command, stdout=output, stderr=subprocess.STDOUT,
                                       start_new_session=True)
        deadline = time.monotonic() + SCREENSHOT_TIMEOUT_S
        try:
            while process.poll() is None and SCREENSHOT_WRITTEN not in log.read_bytes():
                if time.monotonic() > deadline:
                    raise subprocess.TimeoutExpired(command, SCREENSHOT_TIMEOUT_S)
                time.sleep(SCREENSHOT_POLL_S)
        finally:
            _stop(process)
        said = log.read_bytes()
    if not png.is_file() or SCREENSHOT_WRITTEN not in said:
        raise subprocess.CalledProcessError(process.returncode, command, output=said[-2000:])


def _stop(process: subprocess.Popen) -> None:
    """Chromium and every process it started (they share its session)."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(process.pid, signal.SIGKILL)
    process.wait()


def drawn_scene_fraction(png: Path) -> float:
    """The fraction of the picture in saturated colour: the table and objects (Meshcat's background,
    grid and the arm are grey)."""
    from PIL import Image

    hsv = np.asarray(Image.open(png).convert("RGB").convert("HSV"), dtype=float) / 255.0
    return float(np.mean((hsv[..., 1] > 0.3) & (hsv[..., 2] > 0.15)))


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    args.out = args.out or Path(f"reports/grasp_{args.policy}.html")
    program_logging()
    try:
        robot = get_robot(args.robot, args.hand)
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
