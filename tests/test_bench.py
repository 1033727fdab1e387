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


def test_the_stage_clock_gives_each_stage_its_own_time_and_restores_what_it_wrapped():
    import time
    import types

    from drake_grasp.apps.bench import StageClock

    work = types.SimpleNamespace()
    work.inner = lambda: time.sleep(0.05)

    def outer():
        time.sleep(0.03)
        work.inner()

    work.outer = outer
    original = work.inner
    clock = StageClock()
    clock.wrap(work, "outer", "outer")
    clock.wrap(work, "inner", "inner")
    work.outer()
    work.outer()
    clock.restore()
    assert 0.06 <= clock.seconds["outer"] < 0.1  # its own sleeps only (0.16 s with the inner stage)
    assert clock.seconds["inner"] >= 0.1
    assert work.inner is original
