"""The "nothing graspable" stop chosen on logged closed-loop runs (`drake_grasp.grasp_threshold`)."""

import json
from pathlib import Path

import pytest

from drake_grasp.apps.grasp_threshold import GRID, choose, cut_report, main
from drake_grasp.results import cut_at_grasp_threshold

REPORT = Path(__file__).resolve().parents[1] / "reports" / "default_choice" / "current_validation_long.json"


@pytest.fixture(scope="module")
def runs() -> list[dict]:
    return json.loads(REPORT.read_text())["runs"]


def test_a_run_cut_at_no_threshold_is_the_logged_run(runs):
    for run in runs:
        cut = cut_at_grasp_threshold(run, 0.0)
        assert not cut["stopped"] and cut["attempts"] == run["attempts"]
        for rate in ("grasp_success_rate", "completion_rate", "planning_success_rate"):
            assert cut[rate] == pytest.approx(run[rate])


def test_a_run_is_cut_at_its_first_attempt_scored_under_the_threshold(runs):
    run = next(r for r in runs if min(a["score"] for a in r["attempt_log"]) < 0.6)
    first_low = next(k for k, a in enumerate(run["attempt_log"]) if a["score"] < 0.6)
    cut = cut_at_grasp_threshold(run, 0.6)
    assert cut["stopped"] and cut["attempts"] == first_low
    assert cut["successes"] == sum(a["success"] for a in run["attempt_log"][:first_low])
    # A higher threshold never keeps more attempts.
    kept = [cut_report(runs, t)["attempts"] for t in GRID]
    assert kept == sorted(kept, reverse=True) and kept[0] == sum(r["attempts"] for r in runs)


def rows(success_and_completion: list[tuple[int, int, float]]) -> list[dict]:
    """Report rows over GRID from (successes, attempts, completion) per threshold."""
    return [{"threshold": t, "successes": s, "attempts": a, "completion_rate": c}
            for t, (s, a, c) in zip(GRID, success_and_completion, strict=False)]


def test_the_choice_is_the_best_success_within_the_completion_allowed():
    gains = [(90, 100, 1.0), (90, 99, 1.0), (90, 95, 0.995), (88, 90, 0.97)] + [(80, 81, 0.9)] * 13
    assert choose({"a": rows(gains)}, max_completion_loss=0.01) == GRID[2]  # 0.97 costs too much
    assert choose({"a": rows(gains)}, max_completion_loss=0.05) == GRID[3]
    # A second report that loses completion from the first threshold on keeps the stop off.
    flat_loss = [(10, 10, 1.0)] + [(9, 9, 0.9)] * 16
    assert choose({"a": rows(gains), "b": rows(flat_loss)}, max_completion_loss=0.01) == 0.0


def test_the_command_writes_its_choice_and_refuses_what_is_not_a_plain_report(tmp_path, capsys):
    out = tmp_path / "choice"
    assert main(["--validation", str(REPORT), "--out", str(out)]) == 0
    result = json.loads(out.with_suffix(".json").read_text())
    assert result["chosen"] in GRID and "grasp threshold" in out.with_suffix(".md").read_text()
    with_stop = json.loads(REPORT.read_text())
    with_stop["cell"]["grasp_threshold"] = 0.5
    (tmp_path / "stopped.json").write_text(json.dumps(with_stop))
    (tmp_path / "other.json").write_text("{}")
    for bad in ("stopped.json", "other.json", "missing.json"):
        capsys.readouterr()
        assert main(["--validation", str(tmp_path / bad), "--out", str(out)]) == 2
        assert capsys.readouterr().err.count("\n") == 1
