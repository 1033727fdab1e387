"""The field's clutter benchmark: rates pooled over rounds with bootstrap intervals, the "nothing graspable"
stop replayed on logged runs and chosen on validation reports, and the table beside the published numbers."""

import dataclasses as dc
import json

import numpy as np
import pytest

from drake_grasp.apps.experiments import main as experiments
from drake_grasp.cell.episode import EpisodeResult
from drake_grasp.evaluation.benchmark import (
    PUBLISHED,
    choose_threshold,
    cut_at_grasp_threshold,
    field_rates,
    pooled_rate,
    predicts_stability,
    threshold_sweep,
)
from drake_grasp.evaluation.config import EvaluationConfig, LoopConfig, load_config, load_table
from drake_grasp.evaluation.runs import report_header, write_report


def logged_run(seed: int, outcomes: list[tuple[bool, float]], num_objects: int = 5,
               failed_plans: int = 0) -> dict:
    """A run's report entry whose attempts had these (success, p_s) and p_h 1, after `failed_plans` failed
    plans."""
    log = [{"success": False, "planned": False, "p_s": 0.9, "p_h": 1.0, "repeat": False}] * failed_plans
    log += [{"success": ok, "planned": True, "p_s": p_s, "p_h": 1.0, "repeat": False} for ok, p_s in outcomes]
    successes = sum(ok for ok, _ in outcomes)
    result = EpisodeResult(seed=seed, num_objects=num_objects, attempts=len(log), successes=successes,
                           plans_tried=len(log), plans_succeeded=len(outcomes), objects_grasped=successes,
                           end_reason="1 consecutive failures", attempt_log=log)
    return result.to_dict()


def test_pooled_rates_count_as_the_field_does_with_a_seeded_interval_over_rounds():
    rate = pooled_rate([4, 1, 5], [5, 2, 5])  # 10 of 12, not the mean of 0.8, 0.5 and 1.0
    assert rate.rate == pytest.approx(10 / 12) and (rate.numerator, rate.denominator) == (10, 12)
    assert rate.low < rate.rate < rate.high <= 1.0
    assert pooled_rate([4, 1, 5], [5, 2, 5]) == rate  # the same rounds: the same interval
    many = pooled_rate([4, 1, 5] * 30, [5, 2, 5] * 30)
    assert many.rate == pytest.approx(rate.rate) and many.high - many.low < (rate.high - rate.low) / 3
    assert np.isnan(pooled_rate([0], [0]).rate) and pooled_rate([0], [0]).text() == "-"
    gsr, dr = field_rates([logged_run(0, [(True, 0.9), (False, 0.4)], failed_plans=2),
                           logged_run(1, [(True, 0.9)] * 5)])
    # A failed plan executes nothing: out of the grasp rate (the field's floating hand never plans).
    assert (gsr.numerator, gsr.denominator, dr.numerator, dr.denominator) == (6, 7, 6, 10)


def test_the_stop_cuts_a_logged_run_exactly_where_it_would_have_ended_it():
    run = logged_run(0, [(True, 0.9), (True, 0.6), (False, 0.3)])
    assert cut_at_grasp_threshold(run, 0.0) == {"attempts": 3, "plans_succeeded": 3, "successes": 2,
                                                "objects_grasped": 2, "num_objects": 5, "stopped": False}
    assert cut_at_grasp_threshold(run, 0.5) == {"attempts": 2, "plans_succeeded": 2, "successes": 2,
                                                "objects_grasped": 2, "num_objects": 5, "stopped": True}
    assert cut_at_grasp_threshold(run, 0.7)["attempts"] == 1
    rand = logged_run(1, [(False, 0.5)])
    rand["attempt_log"][0].update(p_s=None, p_h=None)  # a policy without p_s never stops
    assert cut_at_grasp_threshold(rand, 0.9)["attempts"] == 1


def test_the_threshold_is_chosen_for_grasp_success_without_costing_declutter():
    # Failures scored 0.3-0.4, successes 0.6 and over: 0.5 removes every failure and no success.
    validation = [logged_run(0, [(True, 0.9), (True, 0.6), (False, 0.3)]),
                  logged_run(1, [(True, 0.8), (False, 0.4)]),
                  logged_run(2, [(True, 0.7)] * 5)]
    thresholds = [0.0, 0.5, 0.65]
    sweep = threshold_sweep(validation, thresholds)
    assert [row["stopped"] for row in sweep] == [0, 2, 2]
    assert sweep[1]["gsr"].rate == 1.0 and sweep[1]["dr"].rate == sweep[0]["dr"].rate
    assert sweep[2]["dr"].rate < sweep[0]["dr"].rate  # 0.65 stops before a success too
    assert choose_threshold([sweep]) == 0.5
    assert choose_threshold([threshold_sweep(validation[2:], thresholds)]) == 0.0  # nothing to gain: off


def test_the_benchmark_table_pools_over_rounds_beside_the_published_numbers(tmp_path, capsys):
    table = tmp_path / "table.yaml"
    table.write_text("base: {objects: novel}\nruns: 2\nentries:\n"
                     "  - {scenario: benchmark_pile, policy: rand}\n")
    config = dc.replace(load_table(str(table)).evaluations()[0], objects="novel")
    assert config.scenario == "benchmark_pile" and config.runs == 2
    out = tmp_path / "out"
    runs = [logged_run(0, [(True, 0.9), (False, 0.3)]), logged_run(1, [(True, 0.9)] * 5)]
    write_report(out / "panda_benchmark_pile_rand.json", report_header(config), config.seeds, runs)
    assert experiments(["--config", str(table), "--out", str(out), "--table-only"]) == 0
    text = (out / "table.md").read_text()
    assert "| benchmark_pile (novel) | RAND | 2 | 85.7 [" in text  # 6 of 7 grasps
    assert "(6/7) | 60.0 [" in text and "(6/10) |" in text  # 6 of 10 objects
    vgn_gsr, vgn_dr = PUBLISHED["benchmark_pile"]["VGN"]
    assert f"VGN, published | | {vgn_gsr:.1f} | {vgn_dr:.1f} |" in text
    assert "floating hand" in text

    # A grasp threshold labels the rows it can stop: not RAND's, whose attempts predict no p_s.
    table.write_text(table.read_text().replace("base: {objects: novel}",
                                               "base: {objects: novel, loop: {grasp_threshold: 0.5}}"))
    config = dc.replace(load_table(str(table)).evaluations()[0], objects="novel")
    unpredicted = [logged_run(0, [(True, None), (False, None)])]
    write_report(out / "panda_benchmark_pile_rand.json", report_header(config), config.seeds[:1], unpredicted)
    assert experiments(["--config", str(table), "--out", str(out), "--table-only"]) == 0
    text = (out / "table.md").read_text()
    assert "| benchmark_pile (novel) | RAND | 1 |" in text and "stop under" not in text
    assert predicts_stability([logged_run(0, [(True, 0.9)])]) and not predicts_stability(unpredicted)


def test_the_benchmark_preset_and_the_objects_option(tmp_path, capsys):
    table = load_table("benchmark_table")
    assert {(c.scenario, c.policy, c.selection.cnn_weights) for c in table.evaluations()} == {
        (s, p, w) for s in ("benchmark_pile", "benchmark_packed")
        for p, w in (("rand", "models/grasp_cnn_all.pt"), ("cnn_rp", "models/grasp_cnn_all.pt"),
                     ("cnn_rp", "models/grasp_cnn_household_40N.pt"))}
    assert table.runs >= 100
    for config in table.evaluations():  # the field's rounds: two failed grasps in a row end one
        scenario = config.load_scenario()
        assert (scenario.max_consecutive_failures, scenario.max_consecutive_plan_failures) == (2, 5)
    assert experiments(["--config", "benchmark_table", "--objects", str(tmp_path / "none"), "--out",
                        str(tmp_path / "out"), "--table-only"]) == 2
    assert "unknown object set" in capsys.readouterr().err  # a missing folder: one line, exit 2
    with pytest.raises(ValueError, match="grasp_threshold"):
        dc.replace(EvaluationConfig(), loop=dc.replace(EvaluationConfig().loop, grasp_threshold=1.5)).check()
    header = report_header(EvaluationConfig())
    assert "grasp_threshold" not in header["evaluation"]["loop"]  # off: older reports stay one experiment
    assert json.dumps(header)  # (written whole into reports)


def test_the_benchmark_grips_force_controlled_on_gpg_candidates_an_evaluation_of_its_own():
    """The benchmark table grips force-controlled on GPG's candidates (the hand stopped at the table) and
    stops at its grasp threshold; its reports are another experiment (header), while an evaluation without
    them keeps the header its older reports have."""
    config = load_table("benchmark_table").evaluations()[1]
    scenario = config.load_scenario()
    assert 0.0 < config.grip_force == scenario.control.grip_force
    assert config.sampler == "gpg" and scenario.sampling.sampler == "gpg"
    assert config.gpg_stop_at_table and scenario.sampling.gpg_stop_at_table
    assert 0.0 < config.loop.grasp_threshold < 1.0
    header = report_header(config)
    assert header["physics"]["grip_force"] == header["evaluation"]["grip_force"] == config.grip_force
    assert header["evaluation"]["sampler"] == "gpg"
    assert header["evaluation"]["loop"]["grasp_threshold"] == config.loop.grasp_threshold
    plain = dc.replace(config, grip_force=0.0, sampler="", loop=dc.replace(config.loop, grasp_threshold=0.0))
    assert "grip_force" not in report_header(plain)["physics"]
    assert not {"grip_force", "sampler"} & set(report_header(plain)["evaluation"])
    assert "grasp_threshold" not in report_header(plain)["evaluation"]["loop"]
    assert plain.load_scenario().control.grip_force is None
    assert plain.load_scenario().sampling.sampler == "uniform"
    with pytest.raises(ValueError, match="grip_force"):
        dc.replace(config, grip_force=500.0).check()
    with pytest.raises(ValueError, match="sampler must be one of"):
        dc.replace(config, sampler="best").check()


def test_grasp_threshold_chooses_on_validation_reports_and_names_bad_ones(tmp_path, capsys):
    from drake_grasp.apps.grasp_threshold import main as grasp_threshold

    config = EvaluationConfig(scenario="benchmark_pile", objects="novel", runs=3)
    runs = [logged_run(0, [(True, 0.9), (True, 0.6), (False, 0.3)]),
            logged_run(1, [(True, 0.8), (False, 0.4)]), logged_run(2, [(True, 0.7)] * 5)]
    report = tmp_path / "validation.json"
    write_report(report, report_header(config), config.seeds, runs)
    assert grasp_threshold(["--validation", str(report), "--out", str(tmp_path / "choice")]) == 0
    choice = json.loads((tmp_path / "choice.json").read_text())
    assert 0.4 < choice["chosen"] <= 0.6  # above every failure's 0.3-0.4, at or under every success's 0.6
    assert "grasp threshold **" in (tmp_path / "choice.md").read_text()
    for run in runs:
        for attempt in run["attempt_log"]:
            attempt["p_s"] = None  # RAND's report: nothing to choose on
    write_report(report, report_header(config), config.seeds, runs)
    capsys.readouterr()
    assert grasp_threshold(["--validation", str(report)]) == 2
    assert "predicts no p_s" in capsys.readouterr().err


def test_grasp_threshold_replays_only_stops_at_or_above_the_one_the_runs_ran_with(tmp_path):
    """Rounds that ran with the stop at 0.35 cannot say what 0.2 would have done: the grid starts at 0.35,
    and when no higher stop gains, the choice is the stop they ran with (not 0, off)."""
    from drake_grasp.apps.grasp_threshold import main as grasp_threshold

    config = EvaluationConfig(scenario="benchmark_pile", objects="novel", runs=2,
                              loop=LoopConfig(grasp_threshold=0.35))
    runs = [logged_run(0, [(True, 0.9), (True, 0.5), (True, 0.4)]), logged_run(1, [(True, 0.8)] * 5)]
    report = tmp_path / "validation.json"
    write_report(report, report_header(config), config.seeds, runs)
    assert grasp_threshold(["--validation", str(report), "--out", str(tmp_path / "choice")]) == 0
    choice = json.loads((tmp_path / "choice.json").read_text())
    assert choice["ran_with"] == 0.35 and choice["thresholds"][0] == min(choice["thresholds"]) == 0.35
    assert choice["chosen"] == 0.35  # every higher stop ends a round before a success
    assert "ran with the stop at 0.35" in (tmp_path / "choice.md").read_text()


def test_a_table_entry_with_other_cnn_weights_gets_its_own_report_and_row(tmp_path):
    from drake_grasp.apps.experiments import report_name

    table = tmp_path / "table.yaml"
    table.write_text("runs: 1\nentries:\n  - {scenario: benchmark_pile, policy: cnn_rp}\n"
                     "  - {scenario: benchmark_pile, policy: cnn_rp, cnn_weights: models/grasp_cnn.pt}\n")
    default, other = load_table(str(table)).evaluations()
    assert other.selection.cnn_weights == "models/grasp_cnn.pt" and other.selection.hold_weights
    assert report_name("panda", default) == "panda_benchmark_pile_cnn_rp.json"
    assert report_name("panda", other) == "panda_benchmark_pile_cnn_rp_grasp_cnn.json"
    out = tmp_path / "out"
    for config in (default, other):
        config = dc.replace(config, objects=config.object_set())  # (as experiments runs it)
        write_report(out / report_name("panda", config), report_header(config), config.seeds,
                     [logged_run(0, [(True, 0.9)] * 5)])
    assert experiments(["--config", str(table), "--out", str(out), "--table-only"]) == 0
    text = (out / "table.md").read_text()
    assert "| OURS (CNN x RP) | 1 |" in text and "| OURS (CNN x RP), grasp_cnn | 1 |" in text


def test_a_table_entry_can_stop_at_its_own_threshold_and_entries_may_not_share_a_report(tmp_path, capsys):
    table = tmp_path / "table.yaml"
    table.write_text("base: {loop: {grasp_threshold: 0.5}}\nruns: 1\nentries:\n"
                     "  - {scenario: benchmark_pile, policy: cnn_rp}\n"
                     "  - {scenario: benchmark_pile, policy: cnn_rp, cnn_weights: models/grasp_cnn.pt, "
                     "grasp_threshold: 0.35}\n")
    base, own = load_table(str(table)).evaluations()
    assert base.loop.grasp_threshold == 0.5 and own.loop.grasp_threshold == 0.35
    table.write_text("runs: 1\nentries:\n  - {scenario: benchmark_pile, policy: cnn_rp}\n"
                     "  - {scenario: benchmark_pile, policy: cnn_rp, grasp_threshold: 0.35}\n")
    assert experiments(["--config", str(table), "--out", str(tmp_path / "out"), "--table-only"]) == 2
    assert "would write one report" in capsys.readouterr().err
    table.write_text("runs: 1\nentries:\n"
                     "  - {scenario: benchmark_pile, policy: cnn_rp, grasp_threshold: 1.5}\n")
    with pytest.raises(ValueError, match="grasp_threshold must be in"):
        load_table(str(table))


def test_the_benchmark_preset_is_the_tables_household_row_one_scene_at_a_time():
    """`simulate --config benchmark [--scenario benchmark_packed]` runs what the table's OURS rows run:
    the same experiment in its report's header (so its runs are the table's), not the scenario's own
    uniform candidates and spring grip."""
    ours = {c.scenario: c for c in load_table("benchmark_table").evaluations()
            if c.policy == "cnn_rp" and "household" in c.selection.cnn_weights}
    single = load_config("benchmark")
    for scenario in ("benchmark_pile", "benchmark_packed"):
        config = dc.replace(single, scenario=scenario)
        assert report_header(config) == report_header(dc.replace(ours[scenario], runs=config.runs))
    assert load_config(None).experiment() != single.experiment()


def test_a_report_made_under_another_run_rule_is_another_experiment(tmp_path):
    """The header records how a run is judged and what ends it where the scenario sets it (the field's
    rounds judge a grasp held and end at the second failed grasp in a row): a report of rounds that ended
    at the first, or judged by the paper's rule, is not resumed under the field's."""
    from drake_grasp.evaluation.runs import finished_runs

    config = load_table("benchmark_table").evaluations()[1]
    header = report_header(config)
    assert header["run_rules"] == {"success_rule": "held", "max_consecutive_failures": 2,
                                   "max_consecutive_plan_failures": 5}
    assert "run_rules" not in report_header(EvaluationConfig())  # the scenario's defaults: not recorded
    report = tmp_path / "first_failure.json"
    write_report(report, {**header, "run_rules": {**header["run_rules"], "max_consecutive_failures": 1}},
                 config.seeds[:1], [logged_run(config.seed, [(False, 0.9)])])
    with pytest.raises(ValueError, match="run_rules differ"):
        finished_runs(report, header)
    write_report(report, header, config.seeds[:1], [logged_run(config.seed, [(False, 0.9)])])
    assert len(finished_runs(report, header)) == 1
    lifted = {**header, "run_rules": {k: v for k, v in header["run_rules"].items() if k != "success_rule"}}
    write_report(report, lifted, config.seeds[:1], [logged_run(config.seed, [(False, 0.9)])])
    with pytest.raises(ValueError, match="run_rules differ"):  # judged by the paper's rule: another one
        finished_runs(report, header)


def test_a_scenario_names_a_known_success_rule(tmp_path):
    from drake_grasp.simulation.scenario import load_scenario

    assert load_scenario("benchmark_packed").success_rule == "held"
    assert load_scenario("standard").success_rule == "lifted"
    (tmp_path / "gripped.yaml").write_text("name: gripped\nsuccess_rule: gripped\n")
    with pytest.raises(ValueError, match="success_rule 'gripped' is not one of: lifted, held"):
        load_scenario(str(tmp_path / "gripped.yaml"))
