"""Stage costs of the grasping pipeline on this machine, as a table (and optionally JSON).

Rows: depth render, depth -> point cloud, segmentation (crop + RANSAC),
grasp sampling (N=500), voxelization of 500 grasps on a 20,000-point cloud
(against the plain per-grid numpy loop and the per-point loop, same run), the
stability CNN on 500 grids, selection of 500 ranked candidates (the default policy, and the
GPD and VPG baselines on the same cloud), grasp-trial collection (trials/s on one core), IK
for one grasp, a whole grasp plan (successes and failures separately), the
Reachability Predictor on 100,000 poses in one call (and how many times faster
than planning that is per pose), a warm `GraspDetector` request (640 x 480, 500
candidates, without and with a plan) and the grasp service's requests a second
(two workers, two clients), the physics real-time factor of the
challenging scene (the plant alone; the cell's first attempt with objects
sleeping and not, and at the scenario's own step), the challenging cell's set-up (the objects
dropped and settled, or the state another run settled), and whole runs on one core
with the share of each stage: a standard run with the shipped defaults against
the same run as the cell ran before its speed-ups and with the system's memory
allocator (`drake_grasp.apps.allocator`), and a challenging run.
Timings vary 20-50 % run to run on a shared 2-core machine: compare within a run.
"""

from __future__ import annotations

import argparse
import dataclasses as dc
import json
import signal
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_grasp.apps.allocator import ALLOCATOR_VARIABLE, preloaded_allocator
from drake_grasp.apps.cli import fail, non_negative_int, positive_int, program_logging
from drake_grasp.evaluation.config import EvaluationConfig
from drake_grasp.learning.voxels import CUBE, GRID, voxelize
from drake_grasp.perception.cloud import extract_object_cloud
from drake_grasp.perception.config import WorkspaceBox
from drake_grasp.planning.planner import GraspPlanner
from drake_grasp.policy.sampling import sample_grasps, sample_workspace_poses
from drake_grasp.robot.arms import get_robot
from drake_grasp.robot.config import DEFAULT_TIME_STEP
from drake_grasp.robot.specs import ROBOTS
from drake_grasp.robot.stages import StageClock
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.placement import choose_objects, place_objects
from drake_grasp.simulation.scenario import Scenario, load_scenario
from drake_grasp.simulation.station import Station


def voxelize_per_grid(points_W: np.ndarray, X_WG: np.ndarray, *, grid: int = GRID, cube: float = CUBE,
                      ) -> np.ndarray:
    """The straightforward numpy loop: every point into every grasp frame, one grasp at a time.

    The bench's baseline for `voxelize`; same result.
    """
    points_W = np.asarray(points_W, dtype=np.float64)
    out = np.zeros((len(X_WG), grid, grid, grid), dtype=np.uint8)
    for n, X in enumerate(np.asarray(X_WG, dtype=np.float64)):
        idx = np.floor(((points_W - X[:3, 3]) @ X[:3, :3] + cube / 2) * (grid / cube)).astype(np.int64)
        idx = idx[((idx >= 0) & (idx < grid)).all(axis=1)]
        out[n, idx[:, 0], idx[:, 1], idx[:, 2]] = 1
    return out


def voxelize_naive(points_W: np.ndarray, X_WG: np.ndarray, *, grid: int = GRID,
                   cube: float = CUBE) -> np.ndarray:
    """The per-grasp, per-point loop: the slowest baseline, and the tests' reference."""
    out = np.zeros((len(X_WG), grid, grid, grid), dtype=np.uint8)
    for n, X in enumerate(np.asarray(X_WG, dtype=np.float64)):
        R, p = X[:3, :3], X[:3, 3]
        for q in np.asarray(points_W, dtype=np.float64):
            g = R.T @ (q - p)
            i, j, k = (int(np.floor((c + cube / 2) * (grid / cube))) for c in g)
            if 0 <= i < grid and 0 <= j < grid and 0 <= k < grid:
                out[n, i, j, k] = 1
    return out


def timed(fn: Callable[[], object], repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def row(name: str, seconds: list[float], note: str = "") -> dict:
    return {"stage": name, "n": len(seconds), "median_ms": 1e3 * statistics.median(seconds),
            "mean_ms": 1e3 * statistics.fmean(seconds), "note": note}


def settled_scene(robot_name: str, scenario_name: str, seed: int, camera_scale: int = 1,
                  scenario: Scenario | None = None):
    """A station whose objects have settled, arm at home: (diagram, context, station, simulator, scenario).

    `scenario` (default: the one named) is used as given, its first camera's resolution times `camera_scale`.
    """
    robot, scenario = get_robot(robot_name), scenario or load_scenario(scenario_name)
    sensing = dc.replace(scenario.sensing, camera=scenario.sensing.camera.scaled(camera_scale))
    scenario = dc.replace(scenario, sensing=sensing)
    rng = np.random.default_rng(seed)
    objects = choose_objects(load_object_set(scenario.object_set), scenario.num_objects, rng,
                             scenario.object_scale)
    builder = DiagramBuilder()
    station = builder.AddSystem(Station(scenario=scenario, robot=robot, objects=objects))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant, plant_context = station.plant(), station.plant_context(context)
    place_objects(plant, plant_context, station.scene_graph().model_inspector(), station.object_bodies,
                  scenario, rng)
    station.set_home(context)
    station_context = station.GetMyMutableContextFromRoot(context)
    station.GetInputPort("arm_desired_state").FixValue(
        station_context, np.concatenate([robot.q_home, np.zeros(robot.num_joints)]))
    station.GetInputPort("hand_desired_state").FixValue(station_context, [robot.hand.open_position, 0.0])
    simulator.Initialize()
    return diagram, context, station, simulator, scenario


def bench_perception(rows: list[dict], repeats: int, seed: int) -> np.ndarray:
    diagram, context, station, simulator, scenario = settled_scene("panda", "standard", seed)
    simulator.AdvanceTo(scenario.settle_time)
    plant, plant_context = station.plant(), station.plant_context(context)
    station_context = station.GetMyContextFromRoot(context)
    body = station.object_bodies[0]
    X = plant.EvalBodyPoseInWorld(plant_context, body)

    def render():
        # Nudging one object invalidates the cached image, so every call renders.
        plant.SetFreeBodyPose(plant_context, body, RigidTransform(X.rotation(), X.translation()
                                                                  + [0, 0, 1e-6 * np.random.rand()]))
        return station.GetOutputPort("depth_image").Eval(station_context)

    render()  # the first render pays VTK's start-up
    rows.append(row("depth render 640x480", timed(render, repeats)))
    depth = render()
    cloud_system = station.GetSubsystemByName("depth_to_cloud")
    cloud_context = cloud_system.CreateDefaultContext()
    cloud_system.camera_pose_input_port().FixValue(cloud_context, station.X_WC)

    def to_cloud():
        cloud_system.depth_image_input_port().FixValue(cloud_context, depth)
        return cloud_system.point_cloud_output_port().Eval(cloud_context)

    rows.append(row("depth -> point cloud", timed(to_cloud, repeats)))
    points = to_cloud().xyzs().T.copy()
    workspace = scenario.sensing.workspace
    segment = lambda: extract_object_cloud(points, lower=workspace.lower, upper=workspace.upper)  # noqa: E731
    objects = segment()
    rows.append(row("segmentation (crop, RANSAC)", timed(segment, repeats),
                    f"{len(points)} -> {len(objects)} points"))
    rng = np.random.default_rng(seed)
    rows.append(row("grasp sampling N=500", timed(
        lambda: sample_grasps(objects.points, 500, (0, 90), rng), repeats)))
    return objects.points


def standard_frame(seed: int):
    """The standard scene's depth image [m] once its objects rest, and its camera: (depth, camera)."""
    diagram, context, station, simulator, scenario = settled_scene("panda", "standard", seed)
    simulator.AdvanceTo(scenario.settle_time)
    depth = np.array(station.GetOutputPort("depth_image").Eval(station.GetMyContextFromRoot(context)).data,
                     copy=True).squeeze(-1)
    return depth, scenario.sensing.camera


def bench_detector(rows: list[dict], repeats: int, seed: int, requests: int = 10) -> None:
    """A warm request to a built `GraspDetector` (the standard scene's 640 x 480 frame, 500 candidates,
    the default policy), without and with a plan, torch on one thread (`taskset -c 0` makes it one core);
    and the grasp service's requests a second with two workers and two clients over loopback."""
    import torch

    from drake_grasp.cell.detection import DetectConfig, GraspDetector
    from drake_grasp.policy.config import SelectionConfig
    from drake_grasp.service.client import GraspClient
    from drake_grasp.service.server import GraspServer, ServeConfig

    depth, camera = standard_frame(seed)
    detector = GraspDetector("panda")
    detector.detect(depth=depth, camera=camera, plan=True)  # loads the models and the planner's plant
    precision, threads = detector.cnn_precision, torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        rows.append(row("warm request 640x480, 500 candidates (GraspDetector)",
                        timed(lambda: detector.detect(depth=depth, camera=camera), repeats),
                        f"{detector.config.policy}, no plan, CNN in {precision}, one torch thread"))
        planned = timed(lambda: detector.detect(depth=depth, camera=camera, plan=True), max(2, repeats // 4))
        rows.append(row("warm request 640x480, 500 candidates, with a plan", planned))
        if precision != "float32":
            exact = GraspDetector("panda", DetectConfig(selection=SelectionConfig(cnn_precision="float32")))
            exact.detect(depth=depth, camera=camera)
            rows.append(row("warm request 640x480, 500 candidates, float32 CNN",
                            timed(lambda: exact.detect(depth=depth, camera=camera), repeats),
                            f"{exact.config.policy}, no plan; --cnn-precision float32 (the closed loop's)"))
    finally:
        torch.set_num_threads(threads)
    server = GraspServer(ServeConfig(port=0, workers=2, queue=2))
    try:
        def client(count: int) -> None:
            with GraspClient(server.address) as c:
                for _ in range(count):
                    c.detect(depth, camera, top=1)

        wall = run_clients(client, (requests, requests))
    finally:
        server.stop(1.0)
    rows.append({"stage": "grasp service, 2 workers, 2 clients", "n": 2 * requests,
                 "median_ms": 1e3 * wall / (2 * requests), "mean_ms": 1e3 * wall / (2 * requests),
                 "note": f"{2 * requests / wall:.2f} requests/s over loopback"})


def run_clients(client, counts: tuple[int, ...]) -> float:
    """`client(count)` in one thread per count, all at once: their wall time [s]. A request the service
    refused is a RuntimeError (once every client is done)."""
    import threading

    failures: list[Exception] = []

    def guarded(count: int) -> None:
        try:
            client(count)
        except Exception as e:  # reported below, not lost in the thread
            failures.append(e)

    start = time.perf_counter()
    threads = [threading.Thread(target=guarded, args=(n,)) for n in counts]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    wall = time.perf_counter() - start
    if failures:
        raise RuntimeError(f"the grasp service refused a bench request: {failures[0]}")
    return wall


def resident_mb(pid: int) -> float:
    """A process's resident memory (Linux's /proc) [MB]."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f"no VmRSS for process {pid}")


def bench_service_memory(rows: list[dict], requests: int, seed: int, candidates: int = 100) -> None:
    """The grasp service's resident memory over `requests` requests: `serve` in its own process (two
    workers, `candidates` a request), two clients over loopback sending the standard scene's frame;
    its RSS once 100 requests are answered, every tenth of the way, and at the end."""
    import socket
    import subprocess
    import threading

    from drake_grasp.service.client import GraspClient

    if not Path("/proc/self/status").exists():
        rows.append({"stage": f"grasp service memory, {requests} requests", "n": 0, "median_ms": float("nan"),
                     "mean_ms": float("nan"), "note": "skipped: needs Linux's /proc"})
        return
    depth, camera = standard_frame(seed)
    with socket.socket() as probe:  # a free port
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    server = subprocess.Popen([sys.executable, "-m", "drake_grasp", "serve", "--port", str(port), "--workers",
                               "2", "--candidates", str(candidates)], stdout=subprocess.PIPE, text=True)
    try:
        if not server.stdout.readline().startswith("serving"):
            raise RuntimeError("the grasp service did not start")
        done, lock, samples = [0], threading.Lock(), []
        marks = {min(100, requests), *range(requests // 10, requests + 1, max(requests // 10, 1))}

        def client(count: int) -> None:
            with GraspClient(f"127.0.0.1:{port}") as c:
                for _ in range(count):
                    c.detect(depth, camera, top=1)
                    with lock:
                        done[0] += 1
                        if done[0] in marks:
                            samples.append((done[0], resident_mb(server.pid)))
                            print(f"  {done[0]} requests answered: server RSS {samples[-1][1]:.0f} MB",
                                  file=sys.stderr, flush=True)

        wall = run_clients(client, (requests // 2, requests - requests // 2))
    finally:
        server.send_signal(signal.SIGTERM)
        server.wait(60)
    samples.sort()
    (_, first), (_, last) = samples[0], samples[-1]
    trace = ", ".join(f"{n}: {mb:.0f}" for n, mb in samples)
    rows.append({"stage": f"grasp service memory, {requests} requests", "n": requests,
                 "median_ms": 1e3 * wall / requests, "mean_ms": 1e3 * wall / requests,
                 "note": f"RSS {first:.0f} MB after {samples[0][0]}, {last:.0f} MB after {requests} "
                         f"({last - first:+.1f} MB); MB by requests answered: {trace}"})


def bench_voxels(rows: list[dict], repeats: int, seed: int, count: int = 500) -> np.ndarray:
    """`voxelize` against the per-grid numpy loop and the per-point loop, on one dense real cloud."""
    _, context, station, simulator, scenario = settled_scene("panda", "standard", seed, camera_scale=2)
    simulator.AdvanceTo(scenario.settle_time)
    points = station.GetOutputPort("point_cloud_W").Eval(station.GetMyContextFromRoot(context)).xyzs().T
    workspace = scenario.sensing.workspace
    cloud = extract_object_cloud(points, lower=workspace.lower, upper=workspace.upper).points
    X_WG = sample_grasps(cloud, count, (0, 90), np.random.default_rng(seed))
    voxelize(cloud, X_WG[:2])  # compiles the kernel, or loads it from numba's cache
    batched = timed(lambda: voxelize(cloud, X_WG), repeats)
    per_grid = timed(lambda: voxelize_per_grid(cloud, X_WG), 1)
    per_point = timed(lambda: voxelize_naive(cloud, X_WG[:2]), 1)
    t = statistics.median(batched)
    rows.append(row(f"voxelize {count} grasps, batched", batched,
                    f"{len(cloud)}-point cloud (standard scene, 1280x960 depth); "
                    f"{per_grid[0] / t:.0f}x the per-grid loop, "
                    f"{per_point[0] / 2 * count / t:,.0f}x the per-point loop"))
    rows.append(row(f"voxelize {count} grasps, per-grid numpy loop", per_grid))
    rows.append(row(f"voxelize 2 grasps, per-point loop (x{count // 2} = {per_point[0] * count / 2:.0f} s)",
                    per_point))
    return voxelize(cloud, X_WG)


def bench_cnn(rows: list[dict], grids: np.ndarray, repeats: int) -> None:
    """The stability CNN's forward pass on a batch of grids (the shipped weights if present): the eager
    module in torch's default layout, in channels-last layout, and frozen as selection runs it."""
    import copy

    import torch

    from drake_grasp.learning.cnn import (
        DEFAULT_WEIGHTS,
        GraspCNN,
        GraspStabilityPredictor,
        load_model,
        predict_grids,
    )

    try:
        model, note = load_model(DEFAULT_WEIGHTS)[0], "shipped weights"
    except ValueError as e:
        model, note = GraspCNN().eval(), f"untrained weights ({e}): the cost is the architecture's"
    eager = timed(lambda: predict_grids(model, grids), repeats)
    predictor = GraspStabilityPredictor(copy.deepcopy(model))  # (channels-last converts its module in place)
    channels_last = timed(lambda: predict_grids(predictor.model, grids), repeats)
    frozen = timed(lambda: predictor.predict(grids), repeats)
    gap = np.abs(predictor.predict(grids) - predict_grids(model, grids)).max()
    threads = torch.get_num_threads()
    for name, times in (("eager", eager), ("eager, channels-last", channels_last),
                        ("frozen, channels-last: selection's", frozen)):
        speed = statistics.median(eager) / statistics.median(times)
        extra = f"; {speed:.1f}x eager" if times is not eager else ""
        rows.append(row(f"stability CNN forward, {len(grids)} grids ({name})", times,
                        f"{statistics.median(times) / len(grids) * 1e3:.2f} ms/grid, {threads} threads; "
                        f"{note}{extra}" + (f"; p_s within {gap:.0e} of eager" if times is frozen else "")))


def bench_selection(rows: list[dict], object_points: np.ndarray, robot_name: str, repeats: int, seed: int,
                    count: int = 500) -> None:
    """Object cloud -> `count` ranked candidates with the default CNN_RP (p_r * p_s * p_h: the hold predictor
    included), the CNN on every candidate and staged."""
    from drake_grasp.perception.cloud import ObjectCloud
    from drake_grasp.policy.config import SelectionConfig
    from drake_grasp.policy.scorers import make_scorer
    from drake_grasp.policy.selector import rank_grasps

    robot, cloud = get_robot(robot_name), ObjectCloud(object_points)
    segmentation = next((r["median_ms"] for r in rows if r["stage"].startswith("segmentation")), float("nan"))

    def select(scorer):
        return rank_grasps(cloud, scorer, num_candidates=count, gamma_deg=(0.0, 90.0),
                           rng=np.random.default_rng(seed))

    variants = {"CNN on all": SelectionConfig(staged=False), "staged, the default": SelectionConfig()}
    ranked = {}
    for name, selection in variants.items():
        scorer = make_scorer("cnn_rp", robot, selection)
        times = timed(lambda s=scorer: select(s), repeats)
        ranked[name] = select(scorer)
        total = segmentation + 1e3 * statistics.median(times)
        scored = int(np.isfinite(ranked[name].p_s).sum())
        note = f"CNN on {scored} of {count}, hold predictor on all; with segmentation {total:.0f} ms"
        if name.startswith("staged"):
            same = np.array_equal(ranked[name].X_WG[:10], ranked["CNN on all"].X_WG[:10])
            note += f"; top 10 {'the same as' if same else 'differ from'} scoring all"
        rows.append(row(f"select {count} grasps (cnn_rp, {name})", times, note))


def bench_baseline_selection(rows: list[dict], object_points: np.ndarray, robot_name: str, repeats: int,
                             seed: int, count: int = 500) -> None:
    """The same cloud -> up to `count` ranked candidates by the paper's baselines: GPD with one camera (GPG
    candidates from the surface normals, grasp images, the LeNet), VPG (heightmap, 16 turned q maps) and VPG
    with pushing (16 turned maps of each of its two nets)."""
    from drake_grasp.perception.cloud import ObjectCloud
    from drake_grasp.policy.scorers import make_scorer
    from drake_grasp.policy.selector import rank_grasps

    robot = get_robot(robot_name)
    for policy in ("gpd1c", "vpg", "vpg_push"):
        scorer = make_scorer(policy, robot)

        def select(scorer=scorer):  # a fresh cloud: the scorers keep the last cloud's normals or maps
            return rank_grasps(ObjectCloud(object_points.copy()), scorer, num_candidates=count,
                               gamma_deg=(0.0, 90.0), rng=np.random.default_rng(seed))

        found = len(select())
        rows.append(row(f"select {count} grasps ({policy})", timed(select, min(repeats, 5)),
                        f"{found} candidates ranked"))


def bench_grasp_trials(rows: list[dict], seed: int, count: int) -> None:
    """Stability data collection on one core: one scene, `count` sampled grasps tried in physics."""
    from drake_grasp.evaluation.grasp_collection import scene_trials
    from drake_grasp.robot.task import TrialOutcome

    models = load_object_set("primitives")
    t0 = time.perf_counter()
    data = scene_trials(seed, models=models, scenario_arg="single", seed=seed, per_scene=count)
    seconds = time.perf_counter() - t0
    n = len(data["label"])
    if n == 0:
        rows.append({"stage": "grasp trials, one scene", "n": 0, "median_ms": float("nan"),
                     "mean_ms": float("nan"), "note": "skipped: the object left the camera's view"})
        return
    physics = int((data["outcome"] != TrialOutcome.COLLIDES_ON_APPROACH).sum())
    rows.append(row(f"grasp trials, one scene ({models[data['scene_object'][0]].name})",
                    [seconds / n] * n,
                    f"{n / seconds:.1f} trials/s on one core, scene set-up included; "
                    f"{physics} of {n} simulated, the rest collide on approach"))


def bench_planning(rows: list[dict], robot_name: str, object_points: np.ndarray, count: int,
                   seed: int) -> list[float]:
    robot = get_robot(robot_name)
    planner = GraspPlanner(robot, seed=seed)
    rng = np.random.default_rng(seed)
    X_WG = sample_grasps(object_points, count, (0, 90), rng)
    q_home, X_GT = np.asarray(robot.q_home), robot.hand.X_GT
    ik = []
    for X in X_WG:
        t0 = time.perf_counter()
        if planner.solve_ik_once(RigidTransform(X) @ X_GT, q_home, with_collision=False) is not None:
            ik.append(time.perf_counter() - t0)
    rows.append(row(f"IK one grasp, plain SNOPT ({robot.name}, solved)", ik))
    ok, failed = [], []
    for X in X_WG:
        result = planner.plan(X)
        (ok if result.success else failed).append(result.seconds)
    if ok:
        rows.append(row(f"grasp plan ({robot.name}, success)", ok))
    if failed:
        rows.append(row(f"grasp plan ({robot.name}, failure)", failed))
    return ok + failed


def bench_reachability_predictor(rows: list[dict], robot_name: str, plan_seconds: list[float],
                                 repeats: int, seed: int, count: int = 100_000) -> None:
    """The RP on `count` poses in one call, against the planner per pose."""
    from drake_grasp.learning.rp import ReachabilityPredictor

    try:
        rp = ReachabilityPredictor.load(robot_name)
    except ValueError as e:
        rows.append({"stage": f"RP on {count} poses ({robot_name})", "n": 0, "median_ms": float("nan"),
                     "mean_ms": float("nan"), "note": f"skipped: {e}"})
        return
    box = WorkspaceBox()  # the cell's, from the table up
    poses = sample_workspace_poses(count, [*box.lower[:2], 0.0], box.upper, np.random.default_rng(seed))
    times = timed(lambda: rp(poses), repeats)
    per_pose = statistics.median(times) / count
    ratio = statistics.median(plan_seconds) / per_pose if plan_seconds else float("nan")
    rows.append(row(f"RP on {count} poses, one call ({robot_name})", times,
                    f"{per_pose * 1e6:.2f} us/pose; {ratio:,.0f}x faster than planning a pose (median)"))


def bench_physics(rows: list[dict], seed: int, sim_seconds: float) -> None:
    _, context, _, simulator, scenario = settled_scene("panda", "challenging", seed)
    t0 = time.perf_counter()
    simulator.AdvanceTo(scenario.settle_time)
    settle = time.perf_counter() - t0
    t0 = time.perf_counter()
    simulator.AdvanceTo(context.get_time() + sim_seconds)
    rest = time.perf_counter() - t0
    rows.append({"stage": "physics challenging (30 objects): settling", "n": 1,
                 "median_ms": 1e3 * settle, "mean_ms": 1e3 * settle,
                 "note": f"real-time factor {scenario.settle_time / settle:.2f}"})
    rows.append({"stage": "physics challenging (30 objects): at rest", "n": 1,
                 "median_ms": 1e3 * rest, "mean_ms": 1e3 * rest,
                 "note": f"real-time factor {sim_seconds / rest:.2f}"})


def bench_attempt_physics(rows: list[dict], seed: int) -> None:
    """The challenging scene's settling and first grasp attempt in the cell (CNN x RP): all objects
    awake at the default step, objects sleeping at the default step, and as the scenario runs (if its
    step is another); the same seed each way, its real-time factor."""
    from drake_grasp.cell.diagram import build_cell, run_attempt
    from drake_grasp.evaluation.config import EvaluationConfig
    from drake_grasp.evaluation.runs import executive_config
    from drake_grasp.policy.scorers import make_scorer

    robot, scenario = get_robot("panda"), load_scenario("challenging")
    models = load_object_set(scenario.object_set)
    options = executive_config(EvaluationConfig(robot="panda", policy="cnn_rp"))
    default = scenario.with_time_step(DEFAULT_TIME_STEP)
    variants = {f"sleep off, {1e3 * DEFAULT_TIME_STEP:g} ms step": default.with_object_sleep(False),
                f"sleep on, {1e3 * DEFAULT_TIME_STEP:g} ms step": default.with_object_sleep(True)}
    if scenario.plant_config.time_step != DEFAULT_TIME_STEP:
        variants[f"as it runs ({1e3 * scenario.plant_config.time_step:g} ms step)"] = scenario
    for label, variant in variants.items():
        t0 = time.perf_counter()
        cell = build_cell(robot=robot, scenario=variant, scorer=make_scorer("cnn_rp", robot),
                          object_models=models, seed=seed, cell=options)
        state = run_attempt(cell)
        wall, sim = time.perf_counter() - t0, cell.context.get_time()
        outcome = "success" if state.attempt is not None and state.attempt.success else state.mode.value
        rows.append({"stage": f"challenging: settle + 1st attempt, {label}", "n": 1,
                     "median_ms": 1e3 * wall, "mean_ms": 1e3 * wall,
                     "note": f"real-time factor {sim / wall:.2f} ({sim:.1f} s simulated; {outcome})"})


def bench_settled_scene(rows: list[dict], seed: int) -> None:
    """Setting up a challenging run's cell: dropping and settling its 30 objects, against starting from
    the state another policy's run settled and kept (as `experiments` shares each seed's drop)."""
    import tempfile

    from drake_grasp.cell.diagram import build_cell
    from drake_grasp.policy.scorers import make_scorer
    from drake_grasp.simulation.settled import SettledScenes, SettledState

    robot, scenario = get_robot("panda"), load_scenario("challenging")
    models = load_object_set(scenario.object_set)
    with tempfile.TemporaryDirectory() as folder:
        settled, seconds, states = SettledScenes(folder), {}, []
        for label in ("drop and settle", "from the kept state"):
            t0 = time.perf_counter()
            cell = build_cell(robot=robot, scenario=scenario, scorer=make_scorer("rand", robot),
                              object_models=models, seed=seed, settled=settled)
            seconds[label] = time.perf_counter() - t0
            states.append(SettledState.of(cell.context))
    same = states[0].time == states[1].time and all(
        np.array_equal(a, b) for a, b in zip(states[0].discrete, states[1].discrete, strict=True))
    settle = seconds["drop and settle"]
    notes = {"drop and settle": f"{states[0].time:.1f} s simulated",
             "from the kept state": f"{settle / seconds['from the kept state']:.1f}x faster, "
                                    f"{'the same' if same else 'another'} state"}
    for label, wall in seconds.items():
        rows.append({"stage": f"challenging: set up the cell, {label}", "n": 1, "median_ms": 1e3 * wall,
                     "mean_ms": 1e3 * wall, "note": notes[label]})


def run_stages(config: EvaluationConfig, seed: int) -> tuple[dict, dict[str, float]]:
    """One closed-loop run of `config` on `seed`: (the run's report dict, wall seconds per stage).

    Stages: set-up (the cell built, objects dropped and settled), rendering (the depth camera and its
    point cloud), perception (crop, RANSAC, segments), selection (sampling, the predictors, ranking),
    planning (the grasp plan and the way home), bookkeeping (the executive's state machine, sleeping
    objects, the episode's ledger) and physics (the simulator's own time, the rest of the episode).
    Loading the policy's weights is not counted.
    """
    from drake_grasp.evaluation.runs import run_one

    with StageClock() as clock:  # the functions marked with their stage (`robot.stages`) report to it
        run = run_one(config, seed)
    return run, dict(clock.seconds)


STAGES = ("physics", "rendering", "perception", "selection", "planning", "bookkeeping", "set-up")


def _run_row(label: str, config: EvaluationConfig, seed: int) -> tuple[dict, float]:
    """One run of `config` on one core (torch on one thread) as a bench row, and its wall time per attempt."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        run, stages = run_stages(config, seed)
    finally:
        torch.set_num_threads(threads)
    wall, sim = sum(stages.values()), run["sim_time_s"]
    per_attempt = wall / max(run["attempts"], 1)
    shares = ", ".join(f"{k} {100 * stages.get(k, 0.0) / wall:.0f}%" for k in STAGES)
    note = (f"{run['attempts']} attempts ({run['successes']} lifted), {sim:.1f} s simulated, "
            f"{wall:.1f} s wall, real-time factor {sim / wall:.2f}, {per_attempt:.1f} s/attempt; {shares}")
    return {"stage": label, "n": 1, "median_ms": 1e3 * wall, "mean_ms": 1e3 * wall, "note": note}, per_attempt


def _run_row_with_system_allocator(label: str, config: EvaluationConfig, seed: int) -> tuple[dict, float]:
    """`_run_row` in a fresh process that runs with the system's allocator (glibc's malloc)."""
    import multiprocessing
    import os
    from concurrent.futures import ProcessPoolExecutor

    saved = {key: os.environ.get(key) for key in ("LD_PRELOAD", ALLOCATOR_VARIABLE)}
    os.environ.pop("LD_PRELOAD", None)
    os.environ[ALLOCATOR_VARIABLE] = "system"
    try:  # (the worker starts with the environment as it is at the first submit)
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(1, mp_context=context, initializer=program_logging) as pool:
            return pool.submit(_run_row, label, config, seed).result()
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def bench_standard_run(rows: list[dict], seed: int) -> None:
    """A standard run on one core, the shipped defaults against the cell as it ran before its speed-ups
    (objects never sleep, the 2 ms step, the CNN on every candidate, the system's allocator), same seed:
    wall time per attempt, real-time factor and each stage's share; the defaults also with the system's
    allocator, to show what the allocator alone buys."""
    from drake_grasp.evaluation.config import load_config

    defaults = load_config("default")
    before = dc.replace(defaults, object_sleep="off", time_step=DEFAULT_TIME_STEP,
                        selection=dc.replace(defaults.selection, staged=False))
    label, allocator = "standard scene, one run, one core", preloaded_allocator()
    row_before, slow = _run_row_with_system_allocator(f"{label} (before)", before, seed)
    rows.append(row_before)
    if allocator is not None:
        row_system, system = _run_row_with_system_allocator(f"{label} (defaults, system allocator)", defaults,
                                                            seed)
        rows.append(row_system)
    row_now, fast = _run_row(f"{label} (defaults{allocator_suffix()})", defaults, seed)
    row_now["note"] += f"; {slow / fast:.1f}x faster per attempt than before"
    if allocator is not None:
        row_now["note"] += f", {system / fast:.2f}x the system allocator's"
    rows.append(row_now)


def bench_challenging_run(rows: list[dict], seed: int) -> None:
    """A whole challenging run (30 objects) with the shipped defaults, as the scenario runs, on one core."""
    from drake_grasp.evaluation.config import load_config

    config = dc.replace(load_config("default"), scenario="challenging")
    label = f"challenging scene, one run, one core (defaults{allocator_suffix()})"
    rows.append(_run_row(label, config, seed)[0])


def allocator_suffix() -> str:
    """', tcmalloc_minimal' (the faster allocator this process runs with), or nothing."""
    allocator = preloaded_allocator()
    return "" if allocator is None else ", " + allocator.split(".so")[0].removeprefix("lib")


def format_table(rows: list[dict]) -> str:
    width = max(len(r["stage"]) for r in rows)
    lines = [f"{'stage':<{width}}  {'n':>5}  {'median ms':>10}  {'mean ms':>10}  note",
             "-" * (width + 40)]
    lines += [f"{r['stage']:<{width}}  {r['n']:>5}  {r['median_ms']:>10.2f}  {r['mean_ms']:>10.2f}  "
              f"{r['note']}"
              for r in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp bench", description=__doc__)
    parser.add_argument("--robot", default="panda", help=f"arm for the IK/planning rows: {sorted(ROBOTS)}")
    parser.add_argument("--repeats", type=positive_int, default=20)
    parser.add_argument("--plans", type=positive_int, default=100, help="grasps to plan")
    parser.add_argument("--trials", type=positive_int, default=50, help="grasp trials to run in physics")
    parser.add_argument("--physics-seconds", type=float, default=2.0)
    parser.add_argument("--quick", action="store_true",
                        help="few repeats, no physics or whole-run rows (for tests)")
    parser.add_argument("--seed", type=non_negative_int, default=0)
    parser.add_argument("--json", type=Path, default=None, help="also write the rows here")
    parser.add_argument("--service-memory", type=positive_int, default=None, metavar="N",
                        help="instead of the table: the grasp service's memory over N requests (10000: the "
                             "issue's check, about an hour on two cores)")
    args = parser.parse_args(argv)
    program_logging()
    try:
        get_robot(args.robot)
    except ValueError as e:
        return fail(e)
    repeats, plans = (3, 10) if args.quick else (args.repeats, args.plans)
    rows: list[dict] = []
    if args.service_memory is not None:
        bench_service_memory(rows, args.service_memory, args.seed)
        return write_rows(rows, args.json)
    points = bench_perception(rows, repeats, args.seed)
    grids = bench_voxels(rows, repeats, args.seed)
    bench_cnn(rows, grids, repeats)
    bench_selection(rows, points, args.robot, repeats, args.seed)
    bench_baseline_selection(rows, points, args.robot, repeats, args.seed)
    bench_grasp_trials(rows, args.seed, 5 if args.quick else args.trials)
    plan_seconds = bench_planning(rows, args.robot, points, plans, args.seed)
    bench_reachability_predictor(rows, args.robot, plan_seconds, repeats, args.seed)
    bench_detector(rows, repeats, args.seed, requests=2 if args.quick else 10)
    if not args.quick:
        bench_physics(rows, args.seed, args.physics_seconds)
        bench_attempt_physics(rows, args.seed)
        bench_settled_scene(rows, args.seed)
        bench_standard_run(rows, args.seed)
        bench_challenging_run(rows, args.seed)
    return write_rows(rows, args.json)


def write_rows(rows: list[dict], json_path: Path | None) -> int:
    """Prints the table (and writes its rows to `json_path`); the program's exit code."""
    print(format_table(rows))
    if json_path is not None:
        json_path.parent.mkdir(parents=True, exist_ok=True)
        json_path.write_text(json.dumps({"rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
