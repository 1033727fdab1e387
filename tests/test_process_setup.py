"""How the programs set up their processes: the faster allocator they preload (a program starts again
with it, declines it when told, and a closed-loop run is the same under either allocator) and the
simulation workers' share of the cores."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest
from scenes import one_cube_yaml

from drake_grasp.apps.allocator import ALLOCATOR_VARIABLE, fast_allocator

needs_allocator = pytest.mark.skipif(
    fast_allocator() is None, reason="no tcmalloc or jemalloc here (scripts/setup.sh installs it as root)")

# A program's first step, then whether the process has a faster allocator mapped.
PROBE = ("from drake_grasp.apps.allocator import run_with_fast_allocator\n"
         "run_with_fast_allocator()\n"
         "maps = open('/proc/self/maps').read()\n"
         "print('tcmalloc' in maps or 'jemalloc' in maps)\n")


def clean_env(**extra: str) -> dict[str, str]:
    """This process's environment without a preloaded library or an allocator choice, plus `extra`."""
    env = {k: v for k, v in os.environ.items() if k not in ("LD_PRELOAD", ALLOCATOR_VARIABLE)}
    return {**env, **extra}


@needs_allocator
def test_a_program_starts_again_with_the_faster_allocator_unless_declined():
    fast = subprocess.run([sys.executable, "-c", PROBE], env=clean_env(), capture_output=True, text=True,
                          timeout=120)
    assert fast.returncode == 0 and fast.stdout.strip() == "True", fast.stderr
    system = subprocess.run([sys.executable, "-c", PROBE], env=clean_env(**{ALLOCATOR_VARIABLE: "system"}),
                            capture_output=True, text=True, timeout=120)
    assert system.returncode == 0 and system.stdout.strip() == "False", system.stderr


@pytest.mark.slow
@needs_allocator
def test_a_run_is_the_same_under_either_allocator(tmp_path, cube_folder):
    """simulate on one cube under glibc's allocator and under the faster one: the same report, but for
    wall-clock times."""
    scenario = tmp_path / "one_cube.yaml"
    scenario.write_text(one_cube_yaml(max_attempts=2))
    runs = []
    for allocator in ("system", "fast"):
        report = tmp_path / f"{allocator}.json"
        done = subprocess.run(
            [sys.executable, "-m", "drake_grasp.simulate", "--scenario", str(scenario), "--objects",
             str(cube_folder), "--policy", "cnn_rp", "--runs", "1", "--seed", "1", "--report",
             str(report), "-q"],
            env=clean_env(**{ALLOCATOR_VARIABLE: allocator}), capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr
        (run,) = json.loads(report.read_text())["runs"]
        run.pop("wall_time_s")
        for entry in run["attempt_log"]:
            entry.pop("plan_seconds")
        runs.append(run)
    assert runs[0] == runs[1] and runs[0]["attempts"] >= 1 and runs[0]["sim_time_s"] > 0.5


def test_simulation_workers_share_the_cores_among_them(monkeypatch):
    """Two simulation workers on this machine's cores: torch runs on its share of them in each."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    import torch

    from drake_grasp.apps.cli import simulation_worker

    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(2, mp_context=context, initializer=simulation_worker, initargs=(2,)) as pool:
        threads = pool.submit(torch.get_num_threads).result(timeout=120)
    assert threads == max(1, (os.cpu_count() or 1) // 2)


def child_pids(pid: int) -> list[int]:
    """The processes `pid` started (Linux's /proc)."""
    children = []
    for task in os.listdir(f"/proc/{pid}/task"):
        with open(f"/proc/{pid}/task/{task}/children") as f:
            children += [int(c) for c in f.read().split()]
    return children


def worker_pids(pid: int) -> list[int]:
    """The worker processes `pid` started (not multiprocessing's resource tracker, which ends on its own
    once its parent has)."""
    workers = []
    for child in child_pids(pid):
        with open(f"/proc/{child}/cmdline", "rb") as f:
            if b"spawn_main" in f.read():
                workers.append(child)
    return workers


def alive(pid: int) -> bool:
    """Whether `pid` still runs (a zombie, ended but not yet reaped, does not)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.slow
def test_sigterm_stops_a_run_in_flight_and_keeps_the_finished_ones(tmp_path, cube_folder):
    """`kill` on simulate (a background job's only stop) once a run is in its report: the program ends
    at once with its worker, exit 130, and the report keeps the finished runs for the same command."""
    scenario = tmp_path / "one_cube.yaml"
    scenario.write_text(one_cube_yaml(max_attempts=1))
    report = tmp_path / "report.json"
    command = [sys.executable, "-m", "drake_grasp.simulate", "--scenario", str(scenario), "--objects",
               str(cube_folder), "--policy", "rand", "--runs", "20", "--workers", "1", "--report",
               str(report), "-q"]
    program = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        while not report.exists() and program.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)
        assert program.poll() is None, program.communicate()
        workers = worker_pids(program.pid)
        program.send_signal(signal.SIGTERM)
        out, err = program.communicate(timeout=60)
    finally:  # a program that outlives the test is stopped, with its workers
        for pid in child_pids(program.pid) if program.poll() is None else []:
            os.kill(pid, signal.SIGKILL)
        program.kill()
    assert program.returncode == 130, err
    assert "Traceback" not in err, err  # (the pool's own thread included)
    assert "interrupted after" in err and "rerun the same command to resume" in err
    assert workers and not any(alive(pid) for pid in workers)
    kept = json.loads(report.read_text())
    assert 1 <= len(kept["runs"]) < 20 and not kept["complete"]


def test_a_worker_quieted_before_it_imports_drake_prints_no_info_lines():
    # A spawned worker's initializer runs before the job's modules import pydrake, whose import sets
    # Drake's logger to INFO; a planner's collision checker then logs a line per build.
    code = ("from drake_grasp.robot.log import program_logging\n"
            "program_logging()\n"
            "from drake_grasp.planning.planner import GraspPlanner\n"
            "from drake_grasp.robot.specs import ROBOTS\n"
            "GraspPlanner(ROBOTS['panda'], seed=0)\n"
            "print('built')\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                          env=clean_env())
    assert done.returncode == 0 and done.stdout.strip() == "built", done.stderr
    assert "INFO" not in done.stderr
