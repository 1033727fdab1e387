import json

import pytest

from drake_grasp.apps.policy_trials import main
from drake_grasp.policy.choice_trials import parse_variant, summarize
from drake_grasp.stats import sign_test_p, wilson_ci95


def test_variants_are_selection_configs_by_name():
    assert parse_variant("default").selection.hold_weights == "models/grasp_hold.pt"
    v = parse_variant("mine=cnn_weights:models/grasp_cnn.pt,hold_weights:none,finger_symmetry:true,"
                      "robust_top:4,hold_z_scale:0.25")
    assert v.name == "mine" and v.selection.cnn_weights == "models/grasp_cnn.pt"
    assert v.selection.hold_weights is None and v.selection.finger_symmetry and v.selection.robust_top == 4
    assert v.selection.hold_z_scale == 0.25
    for bad, message in [("=staged:true", "needs a name"), ("x=colour:red", "FIELD:VALUE"),
                         ("x=staged:maybe", "true or false"), ("x=robust_top:-2", "robust_top")]:
        with pytest.raises(ValueError, match=message):
            parse_variant(bad)


def _pick(outcome: str, point: float) -> dict:
    return {"rank": 0, "outcome": outcome, "object": "mug", "grasp_point": [point, 0.0, 0.05],
            "approach_angle_deg": 10.0}


def test_summary_pairs_each_variant_with_the_first_where_their_choices_differ():
    scenes = [  # (a's first choice, b's): same candidate twice, then a alone, b alone (twice), both fail
        (_pick("success", 0.1), _pick("success", 0.1)),
        (_pick("success", 0.2), _pick("object slipped", 0.3)),
        (_pick("closed on nothing", 0.4), _pick("success", 0.5)),
        (_pick("closed on nothing", 0.6), _pick("success", 0.7)),
        (_pick("object slipped", 0.8), _pick("closed on nothing", 0.9)),
    ]
    records = [{"scene": k, "choices": {"a": [a], "b": [b]}} for k, (a, b) in enumerate(scenes)]
    records.append({"scene": 9, "objects": ["mug"], "points": 0, "choices": {}})  # rolled out of view
    summary = summarize(records, ["a", "b"])
    assert summary["scenes"] == 6 and summary["scenes_with_choices"] == 5
    a, b = summary["variants"]["a"], summary["variants"]["b"]
    assert (a["first_choice_success"], b["first_choice_success"], a["first_choices"]) == (2, 3, 5)
    assert a["first_choice_outcomes"] == {"success": 2, "closed on nothing": 2, "object slipped": 1}
    assert summary["paired"]["b"] == {"against": "a", "same_first_choice": 1, "different_first_choice": 4,
                                      "wins": 2, "losses": 1, "sign_test_p": 1.0}
    assert sign_test_p(0, 5) == pytest.approx(0.0625) and sign_test_p(0, 0) == 1.0
    low, high = wilson_ci95(2, 5)
    assert 0.05 < low < 0.4 < high < 0.8


def test_policy_trials_tries_each_variants_first_choice_in_physics_and_resumes(tmp_path, capsys):
    """One pile scene of the primitives: the default and the paper's selection each choose among the same
    candidates and their choices are tried with the floating hand; a rerun continues the job."""
    out = tmp_path / "blocks"
    argv = ["--objects", "primitives", "--scenario", "pile", "--scenes", "1", "--seed", "3", "--workers", "1",
            "--variant", "default", "--variant", "paper=hold_weights:none", "--out", str(out)]
    assert main(argv) == 0
    lines = out.with_name("blocks.jsonl").read_text().splitlines()
    assert json.loads(lines[0])["job"]["variants"]["paper"]["hold_weights"] is None
    record = json.loads(lines[1])
    assert record["scene"] == 0 and record["points"] > 100 and 1 <= record["trials"] <= 2
    picks = [record["choices"][v][0] for v in ("default", "paper")]
    assert {p["trial"] for p in picks} == set(range(record["trials"]))  # one trial for a shared choice
    for variant in ("default", "paper"):
        (pick,) = record["choices"][variant]
        assert pick["outcome"] in ("success", "closed on nothing", "object slipped", "not in the hand",
                                   "not lifted", "hand collides on approach")
        assert 0.0 < pick["p_s"] <= 1.0 and 0.0 < pick["p_r"] <= 1.0
    assert record["choices"]["paper"][0]["p_h"] is None and record["choices"]["default"][0]["p_h"] > 0
    summary = json.loads(out.with_name("blocks.json").read_text())
    assert summary["variants"]["default"]["first_choices"] == 1 and "paper" in summary["paired"]
    assert "first choice lifted" in out.with_name("blocks.md").read_text()
    capsys.readouterr()
    assert main(argv) == 0  # nothing left to run
    assert "resuming: 1 of 1 scenes" in capsys.readouterr().err
    assert len(out.with_name("blocks.jsonl").read_text().splitlines()) == 2
    other = argv[:-4] + ["--variant", "robust=robust_top:3", "--out", str(out)]
    assert main(other) == 2  # another job in the same file
    assert "holds another job" in capsys.readouterr().err


def test_policy_trials_rejects_bad_input(tmp_path, capsys):
    assert main(["--objects", "no_such_set", "--out", str(tmp_path / "x")]) == 2
    assert "no_such_set" in capsys.readouterr().err
    assert main(["--objects", "primitives", "--policy", "best", "--out", str(tmp_path / "x")]) == 2
    assert "unknown policy" in capsys.readouterr().err
    twice = ["--variant", "a", "--variant", "a"]
    assert main(["--objects", "primitives", *twice, "--out", str(tmp_path / "x")]) == 2
    with pytest.raises(SystemExit) as e:
        main(["--objects", "primitives", "--variant", "x=colour:red", "--out", str(tmp_path / "x")])
    assert e.value.code == 2
