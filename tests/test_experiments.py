"""The experiments command: cells of runs into resumable reports, a table and the paper-style charts."""

import argparse
import json

import pytest

from drake_grasp.apps.cli import add_selection_option, selection_config
from drake_grasp.apps.experiments import cells_to_run, main
from drake_grasp.apps.simulate import RunSpec, finished_runs, write_report
from drake_grasp.policy.executive import CellConfig
from drake_grasp.policy.scorers import SelectionConfig

TINY = """
name: tiny
clusters:
  - centre: [0.5, 0.05]
    radius: 0.0
    count: 1
settle_time: 0.6
num_candidates: 50
max_attempts: 1
"""


def test_experiments_fill_every_cell_write_the_table_and_resume(tmp_path, capsys):
    scenario = tmp_path / "tiny.yaml"
    scenario.write_text(TINY)
    out = tmp_path / "out"
    args = ["--runs", "1", "--scenarios", str(scenario), "--policies", "rand,cnn", "--out", str(out),
            "--workers", "2"]
    assert main(args) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert [(c["policy"], c["runs"]) for c in summary["cells"]] == [("rand", 1), ("cnn", 1)]
    assert "| panda | tiny | 3DCNN | 1 |" in (out / "table.md").read_text()
    assert (out / "success_and_completion.png").stat().st_size > 10_000
    report = json.loads((out / "panda_tiny_rand.json").read_text())
    assert report["complete"] and report["runs"][0]["attempts"] == 1
    assert json.loads((out / "panda_tiny_cnn.json").read_text())["selection"]["hold_join_parts"] is True
    capsys.readouterr()
    assert main(args) == 0  # everything is done: nothing runs again
    assert "2 runs (2 already done)" in capsys.readouterr().out
    # The CNN cell is its selection's: plain segments are another experiment, refused with a clear error.
    assert main([*args, "--table-only", "--no-hold-join-parts"]) == 2
    assert "its selection" in capsys.readouterr().err


def test_an_interrupted_table_keeps_its_finished_runs_and_writes_their_table(tmp_path, monkeypatch, capsys):
    import drake_grasp.datasets.shards as shards

    def first_then_ctrl_c(fn, jobs, **kwargs):  # the first run really runs, then Ctrl-C
        yield jobs[0], fn(jobs[0])
        raise KeyboardInterrupt

    monkeypatch.setattr(shards, "run_jobs", first_then_ctrl_c)
    scenario = tmp_path / "tiny.yaml"
    scenario.write_text(TINY)
    out = tmp_path / "out"
    args = ["--runs", "1", "--scenarios", str(scenario), "--policies", "rand,rp", "--out", str(out)]
    assert main(args) == 130
    table = (out / "table.md").read_text()
    assert "| panda | tiny | RAND | 1 |" in table and "RP only" not in table  # only what finished
    assert json.loads((out / "summary.json").read_text())["cells"][0]["runs"] == 1
    assert "the same command goes on" in capsys.readouterr().err
    (out / "table.md").unlink()
    assert main([*args, "--table-only"]) == 0  # the table again, nothing run
    assert "RP only" not in (out / "table.md").read_text() and not (out / "panda_tiny_rp.json").exists()


def test_the_default_cells_are_the_papers_and_policies_given_run_everywhere():
    cells = cells_to_run(["standard", "ablation"], None, top_grasp=True)
    assert [c for c in cells if c[1] == "standard" and not c[2]] == [
        (p, "standard", False) for p in ("rand", "gpd1c", "gpd", "vpg", "cnn_rp")]  # Fig. 7
    assert {c[0] for c in cells if c[1] == "ablation"} == {"rand", "rp", "cnn", "cnn_rp"}  # Table I
    assert [c[0] for c in cells if c[2]] == ["rand", "gpd1c", "gpd", "cnn_rp"]  # VPG is straight down already
    assert cells[0][0] == "rand" and cells[1] == ("rand", "ablation", False)  # policy by policy
    assert cells_to_run(["ablation"], "rand,vpg", top_grasp=True) == [("rand", "ablation", False),
                                                                      ("vpg", "ablation", False)]


def test_the_top_grasp_variant_approaches_straight_down_and_is_its_own_experiment():
    spec = RunSpec("panda", "standard", "cnn_rp", None, CellConfig(), top_grasp=True)
    assert spec.load_scenario().gamma_deg == [0.0, 0.0]
    assert spec.header("panda")["top_grasp"] is True
    assert "top_grasp" not in RunSpec("panda", "standard", "cnn_rp", None, CellConfig()).header("panda")


def test_the_command_line_chooses_the_default_models_or_the_papers():
    parser = argparse.ArgumentParser()
    add_selection_option(parser)
    assert selection_config(parser.parse_args([])) == SelectionConfig()
    paper = parser.parse_args(["--cnn-weights", "models/grasp_cnn.pt", "--hold-weights", "none"])
    assert selection_config(paper) == SelectionConfig(cnn_weights="models/grasp_cnn.pt", hold_weights=None)
    own = selection_config(parser.parse_args(["--selection", "staged", "--hold-weights", "my_hold.pt"]))
    assert own.staged and own.hold_weights == "my_hold.pt" and not own.finger_symmetry
    assert selection_config(parser.parse_args(["--finger-symmetry"])).finger_symmetry
    assert selection_config(parser.parse_args(["--hold-join-parts"])).hold_join_parts
    assert not selection_config(parser.parse_args(["--no-hold-join-parts"])).hold_join_parts
    assert own.cnn_weights == SelectionConfig().cnn_weights == "models/grasp_cnn_all.pt"


def test_staged_selection_and_the_models_are_each_their_own_experiment_for_the_cnn_policies(tmp_path):
    staging = SelectionConfig(staged=True)
    paper_models = SelectionConfig(cnn_weights="models/grasp_cnn.pt", hold_weights=None)
    full = RunSpec("panda", "standard", "cnn_rp", None, CellConfig())
    staged = RunSpec("panda", "standard", "cnn_rp", None, CellConfig(), selection=staging)
    paper = RunSpec("panda", "standard", "cnn_rp", None, CellConfig(), selection=paper_models)
    symmetric = RunSpec("panda", "standard", "cnn_rp", None, CellConfig(),
                        selection=SelectionConfig(finger_symmetry=True))
    assert full.header("panda")["selection"] == {"staged": False, "blocking_voxels": 3, "exact_top": 10,
                                                 "batch_size": 16, "cnn_weights": "models/grasp_cnn_all.pt",
                                                 "hold_weights": "models/grasp_hold.pt",
                                                 "hold_join_parts": True}
    # A report made before the join became the default (its header without the field) is plain segments'.
    unjoined = RunSpec("panda", "standard", "cnn_rp", None, CellConfig(),
                       selection=SelectionConfig(hold_join_parts=False))
    assert "hold_join_parts" not in unjoined.header("panda")["selection"]
    assert staged.header("panda")["selection"]["staged"] is True
    assert symmetric.header("panda")["selection"]["finger_symmetry"] is True  # (off: not in the header)
    robust = RunSpec("panda", "standard", "cnn_rp", None, CellConfig(),
                     selection=SelectionConfig(robust_top=5))
    assert robust.header("panda")["selection"]["robust_top"] == 5
    assert "hold_weights" not in paper.header("panda")["selection"]
    rand = RunSpec("panda", "standard", "rand", None, CellConfig(), selection=staging)
    assert "selection" not in rand.header("panda")  # RAND never runs the CNN
    report = tmp_path / "full.json"
    write_report(report, full.header("panda"), [0], [])
    for other in (staged, paper, symmetric, unjoined):
        with pytest.raises(ValueError, match="its selection"):
            finished_runs(report, other.header("panda"))
    assert finished_runs(report, full.header("panda")) == []
    # The very weights files are part of the experiment: retrained weights under the same name are another.
    assert set(full.header("panda")["weights"]) == {"reachability_panda.pt", "grasp_cnn_all.pt",
                                                    "grasp_hold.pt"}
    assert "weights" not in rand.header("panda")
    retrained = full.header("panda")
    retrained["weights"] = {**retrained["weights"], "grasp_cnn_all.pt": "0123456789ab"}
    write_report(report, retrained, [0], [])
    with pytest.raises(ValueError, match="weights differ"):
        finished_runs(report, full.header("panda"))
