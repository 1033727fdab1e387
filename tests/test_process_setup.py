"""How the programs set up their processes: the faster allocator they preload (a program starts again
with it, declines it when told, and a closed-loop run is the same under either allocator) and the
simulation workers' share of the cores."""

import json
import os
import subprocess
import sys

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
