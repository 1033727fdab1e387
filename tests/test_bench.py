import json

import pytest

from drake_grasp.apps.bench import main


@pytest.mark.slow
def test_bench_prints_the_stage_table(capsys, tmp_path):
    out_json = tmp_path / "bench.json"
    assert main(["--quick", "--json", str(out_json)]) == 0
    table = capsys.readouterr().out
    for stage in ("depth render", "depth -> point cloud", "segmentation", "grasp sampling N=500",
                  "voxelize 500 grasps, batched", "per-grid numpy loop", "stability CNN forward, 500 grids",
                  "select 500 grasps (cnn_rp, staged, the default)", "select 500 grasps (gpd1c)",
                  "select 500 grasps (vpg)",
                  "grasp trials, one scene", "IK one grasp", "grasp plan", "RP on 100000 poses",
                  "warm request 640x480", "with a plan", "grasp service, 2 workers"):
        assert stage in table
    rows = {r["stage"]: r for r in json.loads(out_json.read_text())["rows"]}
    for baseline in ("gpd1c", "vpg", "vpg_push"):  # each ranks its own candidates on the standard scene
        assert int(rows[f"select 500 grasps ({baseline})"]["note"].split()[0]) > 0


@pytest.mark.slow
def test_the_service_memory_row_samples_a_real_server(tmp_path):
    out_json = tmp_path / "memory.json"
    assert main(["--service-memory", "6", "--json", str(out_json)]) == 0
    (row,) = json.loads(out_json.read_text())["rows"]
    assert row["stage"] == "grasp service memory, 6 requests" and row["n"] == 6
    resident = [float(part.split(": ")[1]) for part in row["note"].split("answered: ")[1].split(", ")]
    assert len(resident) == 6 and all(200 < mb < 8000 for mb in resident)  # a served process's RSS [MB]


def test_the_stage_clock_gives_each_stage_its_own_time_and_only_while_it_runs():
    import time

    from drake_grasp.robot.stages import StageClock, stage

    inner = stage("inner")(lambda: time.sleep(0.05))

    @stage("outer")
    def outer():
        time.sleep(0.03)
        inner()

    with StageClock() as clock:
        outer()
        outer()
    outer()  # no clock running: nothing counted
    assert 0.06 <= clock.seconds["outer"] < 0.1  # its own sleeps only (0.16 s with the inner stage)
    assert 0.1 <= clock.seconds["inner"] < 0.14
    with StageClock() as outside, StageClock() as inside:  # the innermost clock counts, then the outer again
        inner()
    assert "inner" in inside.seconds and not outside.seconds
