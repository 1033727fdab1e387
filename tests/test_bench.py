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
                  "select 500 grasps (cnn_rp, staged)", "select 500 grasps (gpd1c)",
                  "select 500 grasps (vpg)",
                  "grasp trials, one scene", "IK one grasp", "grasp plan", "RP on 100000 poses"):
        assert stage in table
    rows = {r["stage"]: r for r in json.loads(out_json.read_text())["rows"]}
    for baseline in ("gpd1c", "vpg"):  # each ranks candidates of its own on the standard scene's objects
        assert int(rows[f"select 500 grasps ({baseline})"]["note"].split()[0]) > 0
