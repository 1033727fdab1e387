"""Evaluations as typed configuration (presets, files, headers) and the experiments command: a table of
evaluations into resumable reports, a table and the paper-style charts."""

import dataclasses as dc
import json

import pytest
from scenes import drawn_fraction

from drake_grasp.apps.experiments import main
from drake_grasp.evaluation.config import EvaluationConfig, load_config, load_table
from drake_grasp.evaluation.runs import executive_config, finished_runs, report_header, write_report
from drake_grasp.policy.config import SelectionConfig

TINY = """
name: tiny
clusters:
  - centre: [0.5, 0.05]
    radius: 0.0
    count: 1
settle_time: 0.6
sampling: {num_candidates: 50}
max_attempts: 1
"""


def tiny_table(tmp_path, policies=("rand", "cnn")) -> str:
    scenario = tmp_path / "tiny.yaml"
    scenario.write_text(TINY)
    table = tmp_path / "table.yaml"
    table.write_text("runs: 1\nentries:\n" + "".join(f"  - {{scenario: {scenario}, policy: {p}}}\n"
                                                     for p in policies))
    return str(table)


@pytest.mark.slow
def test_experiments_fill_every_entry_write_the_table_and_resume(tmp_path, capsys):
    out = tmp_path / "out"
    args = ["--config", tiny_table(tmp_path), "--out", str(out), "--workers", "2"]
    assert main(args) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert [(c["policy"], c["runs"]) for c in summary["reports"]] == [("rand", 1), ("cnn", 1)]
    assert "| panda | tiny | 3DCNN | 1 |" in (out / "table.md").read_text()
    assert drawn_fraction(out / "success_and_completion.png") > 0.02
    report = json.loads((out / "panda_tiny_rand.json").read_text())
    assert report["complete"] and report["runs"][0]["attempts"] == 1
    cnn = json.loads((out / "panda_tiny_cnn.json").read_text())
    assert cnn["evaluation"]["selection"]["hold_join_parts"] is True and cnn["format"] == 3
    capsys.readouterr()
    assert main(args) == 0  # everything is done: nothing runs again
    assert "2 runs (2 already done)" in capsys.readouterr().out


def test_an_interrupted_table_keeps_its_finished_runs_and_writes_their_table(tmp_path, monkeypatch, capsys):
    import drake_grasp.datasets.shards as shards

    def first_then_ctrl_c(fn, jobs, **kwargs):  # the first run really runs, then Ctrl-C
        yield jobs[0], fn(jobs[0])
        raise KeyboardInterrupt

    monkeypatch.setattr(shards, "run_jobs", first_then_ctrl_c)
    out = tmp_path / "out"
    args = ["--config", tiny_table(tmp_path, ("rand", "rp")), "--out", str(out)]
    assert main(args) == 130
    table = (out / "table.md").read_text()
    assert "| panda | tiny | RAND | 1 |" in table and "RP only" not in table  # only what finished
    assert json.loads((out / "summary.json").read_text())["reports"][0]["runs"] == 1
    assert "the same command goes on" in capsys.readouterr().err
    (out / "table.md").unlink()
    assert main([*args, "--table-only"]) == 0  # the table again, nothing run
    assert "RP only" not in (out / "table.md").read_text() and not (out / "panda_tiny_rp.json").exists()
    # The table of a folder with no report of it yet: one line, exit 2.
    assert main([*args[:2], "--out", str(tmp_path / "elsewhere"), "--table-only"]) == 2
    assert capsys.readouterr().err.startswith("error: no report of this table in")


def test_a_run_that_fails_is_named_and_the_others_go_on(tmp_path, monkeypatch, capsys):
    import drake_grasp.datasets.shards as shards

    def first_fails(fn, jobs, **kwargs):  # the first run raises in its worker; the others really run
        assert kwargs["keep_going"]
        yield jobs[0], shards.JobFailure(RuntimeError("a bug in one run"))
        for job in jobs[1:]:
            yield job, fn(job)

    monkeypatch.setattr(shards, "run_jobs", first_fails)
    out = tmp_path / "out"
    assert main(["--config", tiny_table(tmp_path, ("rand", "rp")), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "panda_tiny_rand.json seed 0: failed: RuntimeError: a bug in one run" in err
    assert "1 run(s) failed (panda_tiny_rand.json seed 0)" in err
    assert not (out / "panda_tiny_rand.json").exists()
    assert json.loads((out / "panda_tiny_rp.json").read_text())["runs"][0]["attempts"] == 1


def test_the_paper_table_is_the_papers_figure_7_and_table_1_with_top_grasps():
    table = load_table("paper_table")
    entries = [(e.scenario, e.policy, e.top_grasp) for e in table.entries]
    assert {p for s, p, top in entries if s == "standard" and not top} == {"rand", "gpd1c", "gpd", "vpg",
                                                                          "cnn_rp"}  # Fig. 7
    assert {p for s, p, _ in entries if s == "ablation"} == {"rand", "rp", "cnn", "cnn_rp"}  # Table I
    assert {p for _, p, top in entries if top} == {"rand", "gpd1c", "gpd", "cnn_rp"}  # VPG: down already
    assert {p for s, p, _ in entries if s == "challenging"} == {"rand", "gpd1c", "gpd", "vpg", "vpg_push",
                                                               "cnn_rp"}  # VPG with and without pushes
    assert table.runs == 30 and all(c.runs == 30 for c in table.evaluations())
    with pytest.raises(ValueError, match="unknown table 'nope'"):
        load_table("nope")


def test_presets_and_files_load_typed_and_bad_ones_are_named(tmp_path):
    assert load_config() == load_config("default") == EvaluationConfig()
    paper = load_config("paper")
    assert paper.selection == SelectionConfig(staged=False, cnn_weights="models/grasp_cnn.pt",
                                              hold_weights=None)
    assert paper.loop.paper_loop and paper.loop.transit_ignores_objects
    options = executive_config(paper)
    assert not options.failure_memory and options.reach_threshold == 0 and not options.avoid_observed_objects
    assert executive_config(EvaluationConfig()).reach_threshold > 0  # the RP card's calibrated stop
    own = tmp_path / "own.yaml"
    own.write_text("policy: cnn\nselection: {staged: false}\nmax_attempts: 3\nruns: 2\nseed: 5\n")
    config = load_config(own)
    assert not config.selection.staged and config.max_attempts == 3 and config.seeds == [5, 6]
    assert config.load_scenario().max_attempts == 3
    for text, message in (("object_sleep: maybe\n", "object_sleep must be"), ("polcy: cnn\n", "invalid"),
                          ("scenario: single\n", "for data collection"), ("seed: -1\n", "seed >= 0")):
        own.write_text(text)
        with pytest.raises(ValueError, match=message):
            load_config(own)
    with pytest.raises(ValueError, match="unknown configuration 'papr'"):
        load_config("papr")


def test_a_report_resumes_only_the_very_same_configuration_and_weights(tmp_path):
    full = dc.replace(EvaluationConfig(), objects="primitives")
    header = report_header(full)
    assert header["evaluation"] == full.experiment() and "seed" not in header["evaluation"]
    assert set(header["weights"]) == {"reachability_panda.pt", "grasp_cnn_all.pt", "grasp_hold.pt"}
    report = tmp_path / "full.json"
    write_report(report, header, [0], [])
    other_seeds = report_header(dc.replace(full, seed=3, runs=5))
    assert finished_runs(report, other_seeds) == []  # the same experiment: resumed
    for other in (dc.replace(full, selection=SelectionConfig(staged=False)),
                  dc.replace(full, selection=SelectionConfig(hold_join_parts=False)),
                  load_config("paper"), dc.replace(full, time_step=0.004)):
        with pytest.raises(ValueError, match="its evaluation"):
            finished_runs(report, report_header(dc.replace(other, objects="primitives")))
    rand = report_header(dc.replace(full, policy="rand"))
    assert rand["weights"] == {}  # RAND loads no weights
    # A scenario file that changes its physics between two reports: not the same experiment.
    scenario = tmp_path / "tiny.yaml"
    scenario.write_text(TINY)
    tiny = dc.replace(full, scenario=str(scenario))
    write_report(report, report_header(tiny), [0], [])
    scenario.write_text(TINY + "plant_config: {time_step: 0.004}\n")
    with pytest.raises(ValueError, match="its physics differ"):
        finished_runs(report, report_header(tiny))
    retrained = {**header, "weights": {**header["weights"], "grasp_cnn_all.pt": "0123456789ab"}}
    write_report(report, retrained, [0], [])
    with pytest.raises(ValueError, match="weights differ"):
        finished_runs(report, header)


def test_jobs_go_ten_seeds_at_a_time_and_longest_first_within_them():
    from drake_grasp.apps.experiments import job_order

    table = load_table("paper_table")
    configs = [c for c in table.evaluations() if c.policy == "cnn_rp" and not c.top_grasp]
    jobs = [(i, config, seed) for i, config in enumerate(configs) for seed in range(12)]
    order = job_order(jobs)
    assert sorted(order, key=lambda j: (j[0], j[2])) == sorted(jobs, key=lambda j: (j[0], j[2]))
    first_round = [j for j in order if j[2] < 10]
    assert order[:len(first_round)] == first_round  # seeds 0-9 of every entry before seed 10 of any
    scenarios = [j[1].scenario for j in first_round]
    assert scenarios == sorted(scenarios, key=["challenging", "standard", "ablation"].index)  # longest first
    assert [j[2] for j in first_round if j[1].scenario == "standard"] == list(range(10))


def test_the_entries_of_a_scenario_go_one_after_the_other_so_they_share_the_settled_scenes():
    from drake_grasp.apps.experiments import job_order

    configs = [c for c in load_table("paper_table").evaluations() if c.scenario == "challenging"][:2]
    order = job_order([(i, config, seed) for i, config in enumerate(configs) for seed in range(10)])
    assert [(i, seed) for i, _, seed in order] == [(i, seed) for i in (0, 1) for seed in range(10)]
