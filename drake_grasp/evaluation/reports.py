"""The closed loop's reports read back: tables and charts in the style of the paper's Fig. 7 and Table I.

A report is the JSON that `python -m drake_grasp.simulate --report` writes: one
evaluation (robot, scenario, object set, policy, ...) with its runs. Rates are means over runs
with a 95 % confidence interval (Student's t over the runs), as the paper reports
them; the paper's own number stands beside ours where the paper gives one.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drake_grasp.evaluation.stats import mean_ci95
from drake_grasp.policy.config import SelectionConfig
from drake_grasp.policy.scorers import USES_CNN

RATES = ("grasp_success_rate", "completion_rate", "planning_success_rate")
RATE_NAMES = {"grasp_success_rate": "grasp success", "completion_rate": "completion",
              "planning_success_rate": "planning success"}
POLICY_NAMES = {"rand": "RAND", "cnn": "3DCNN", "rp": "RP only", "cnn_rp": "OURS (CNN x RP)",
                "gpd1c": "GPD1c", "gpd": "GPD", "vpg": "VPG", "vpg_push": "VPG (pushing)"}
POLICY_ORDER = ("rand", "gpd1c", "gpd", "vpg", "vpg_push", "rp", "cnn", "cnn_rp")
SCENARIO_ORDER = ("standard", "challenging", "ablation", "beyond_reach")

# The paper's simulated results (UR5 in V-REP, 30 runs each), where the text gives the number:
# Table I (ablation) in full; of Fig. 7 only what the text states (the figure's bars are not tabulated).
PAPER = {
    ("ablation", "rand"): {"grasp_success_rate": 0.1333, "planning_success_rate": 0.2667},
    ("ablation", "cnn"): {"grasp_success_rate": 0.3267, "planning_success_rate": 0.3733},
    ("ablation", "cnn_rp"): {"grasp_success_rate": 0.8267, "planning_success_rate": 0.9600},
    ("challenging", "cnn_rp"): {"grasp_success_rate": 0.715, "completion_rate": 1.0},
    ("standard", "cnn_rp"): {"completion_rate": 1.0},
}


@dataclass(frozen=True)
class Report:
    """One `simulate` report: its robot, scenario, objects and policy, and its per-run rates."""

    robot: str
    scenario: str
    objects: str
    policy: str
    runs: dict[str, np.ndarray]  # rate -> (runs,)
    path: Path
    top_grasp: bool = False  # candidates approached straight down only (the paper's "top grasping")
    noisy_camera: bool = False  # the depth camera's noise model was on
    cnn_weights: str = ""  # the stability CNN's weights where they are not the default's

    @property
    def num_runs(self) -> int:
        return len(self.runs["grasp_success_rate"])

    def rate(self, name: str) -> tuple[float, float]:
        """(mean over runs, half width of its 95 % interval)."""
        return mean_ci95(self.runs[name])

    def paper(self, name: str) -> float | None:
        if self.objects != "primitives" or self.top_grasp or self.noisy_camera:
            return None
        return PAPER.get((self.scenario, self.policy), {}).get(name)

    @property
    def policy_name(self) -> str:
        """The policy's name in tables, with its CNN weights where they are not the default's."""
        name = POLICY_NAMES.get(self.policy, self.policy)
        return f"{name}, {self.cnn_weights}" if self.cnn_weights else name

    @property
    def label(self) -> str:
        label = self.scenario if self.objects == "primitives" else f"{self.scenario} ({self.objects})"
        variants = {", top grasps": self.top_grasp, ", noisy camera": self.noisy_camera}
        return label + "".join(name for name, on in variants.items() if on)


def read_report(path: str | Path) -> Report | None:
    """The `simulate` report at `path`; None for another kind of JSON."""
    from drake_grasp.evaluation.runs import REPORT_FORMAT

    path = Path(path)
    data = json.loads(path.read_text())
    if not isinstance(data, dict) or data.get("format") != REPORT_FORMAT or "runs" not in data:
        return None
    evaluation = data["evaluation"]
    runs = {rate: np.array([r[rate] for r in data["runs"]], dtype=float) for rate in RATES}
    weights = evaluation["selection"]["cnn_weights"]
    other = evaluation["policy"] in USES_CNN and weights != SelectionConfig().cnn_weights
    return Report(data["robot_name"], data["scenario_name"], evaluation["objects"], evaluation["policy"],
                  runs, path, evaluation["top_grasp"], evaluation["depth_noise"],
                  Path(weights).stem if other else "")


def load_reports(folder: str | Path, robot: str | None = None) -> list[Report]:
    """Every `simulate` report in a folder (not its subfolders), optionally of one robot, in table order."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"no report folder at {folder}")
    reports = [c for p in sorted(folder.glob("*.json")) if (c := read_report(p)) is not None]
    reports = [c for c in reports if robot is None or c.robot == robot]
    return sorted(reports, key=_order)


def _order(report: Report) -> tuple:
    known = report.scenario in SCENARIO_ORDER
    scenario = SCENARIO_ORDER.index(report.scenario) if known else len(SCENARIO_ORDER)
    policy = POLICY_ORDER.index(report.policy) if report.policy in POLICY_ORDER else len(POLICY_ORDER)
    variant = (report.objects != "primitives", report.objects, report.top_grasp, report.noisy_camera)
    return report.robot, scenario, *variant, policy


def _percent(mean: float, half: float) -> str:
    return f"{100 * mean:.1f}" + ("" if np.isnan(half) else f" ± {100 * half:.1f}")


def markdown_table(reports: list[Report]) -> str:
    """Robot, scenario, policy, runs and each rate (mean ± 95 % CI, %), the paper's number in brackets."""
    head = ["robot", "scenario", "policy", "runs", *(RATE_NAMES[r] + " %" for r in RATES)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for c in reports:
        values = []
        for rate in RATES:
            text = _percent(*c.rate(rate))
            if (paper := c.paper(rate)) is not None:
                text += f" [paper {100 * paper:.1f}]"
            values.append(text)
        row = [c.robot, c.label, c.policy_name, str(c.num_runs), *values]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def _grouped_bars(ax, reports: list[Report], groups: list[str], rate: str) -> None:
    """Bars per group (x) and policy (colour), with 95 % intervals; the paper's numbers as black diamonds."""
    names = {c.policy_name: c.policy for c in reports}  # (the same policy with other weights: a colour too)
    policies = sorted(names, key=lambda name: (POLICY_ORDER.index(names[name]) if names[name] in POLICY_ORDER
                                               else len(POLICY_ORDER), name))
    width = 0.8 / max(len(policies), 1)
    paper_drawn = False
    for j, policy in enumerate(policies):
        for i, group in enumerate(groups):
            report = next((c for c in reports if c.policy_name == policy and c.label == group), None)
            if report is None:
                continue
            x = i - 0.4 + width * (j + 0.5)
            mean, half = report.rate(rate)
            error = None if np.isnan(half) else 100 * half
            ax.bar(x, 100 * mean, width, color=f"C{j}", yerr=error, capsize=3,
                   label=policy if i == 0 else None)
            ax.text(x, 2, f"n={report.num_runs}", ha="center", fontsize=7, rotation=90, color="white")
            if (paper := report.paper(rate)) is not None:
                ax.plot(x, 100 * paper, "kD", markersize=5, label=None if paper_drawn else "paper")
                paper_drawn = True
    ax.set_xticks(range(len(groups)), groups)
    ax.set_ylim(0, 105)
    ax.set_ylabel(f"{RATE_NAMES[rate]} (%)")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))


def _finished(fig, path: str | Path | None):
    """The figure laid out, and saved when a path is given."""
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
    return fig


def plot_success_and_completion(reports: list[Report], path: str | Path | None = None):
    """Paper Fig. 7: grasp success (top) and completion (bottom) per scenario and policy; the figure."""
    import matplotlib.pyplot as plt

    reports = [c for c in reports if c.scenario != "ablation"]
    groups = list(dict.fromkeys(c.label for c in reports))
    fig, axes = plt.subplots(2, 1, figsize=(3 + 2.2 * len(groups), 7), sharex=True)
    for ax, rate in zip(axes, ("grasp_success_rate", "completion_rate"), strict=True):
        _grouped_bars(ax, reports, groups, rate)
    robots = sorted({c.robot for c in reports})
    axes[0].set_title(f"Closed-loop grasping in simulation ({', '.join(robots)}); mean over runs, 95 % CI",
                      fontsize=10)
    return _finished(fig, path)


def plot_ablation(reports: list[Report], path: str | Path | None = None):
    """Paper Table I as bars: grasp and planning success per policy in the ablation scene."""
    import matplotlib.pyplot as plt

    reports = [c for c in reports if c.scenario == "ablation"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, rate in zip(axes, ("grasp_success_rate", "planning_success_rate"), strict=True):
        _grouped_bars(ax, reports, ["ablation"], rate)
    fig.suptitle("Ablation of the reachability predictor (paper Table I); mean over runs, 95 % CI",
                 fontsize=10)
    return _finished(fig, path)


def plot_stability_curve(rows: list[dict], path: str | Path | None = None):
    """The stability CNN's held-out accuracy against its training-set size, or its held-out AUROC
    against the number of training objects when the rows have `train_objects` (a `stability_report`)."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    by_objects = "train_objects" in rows[0]
    metric = "auroc" if by_objects else "accuracy"
    sizes = [r["train_objects" if by_objects else "train_grasps"] for r in rows]
    ax.plot(sizes, [r["test_metrics"][metric] for r in rows], "o-", label="held-out scenes")
    if "novel_metrics" in rows[0]:
        ax.plot(sizes, [r["novel_metrics"][metric] for r in rows], "s--", label="objects never trained on")
    if not by_objects:
        ax.axhline(1 - rows[-1]["test_metrics"]["positive_rate"], color="grey", lw=0.8, ls=":",
                   label="always 'unstable'")
    ax.set_xscale("log")
    ax.set_xlabel(f"training objects ({rows[0]['train_grasps']} grasps each point)" if by_objects
                  else "training grasps")
    ax.set_ylabel(f"test {metric.upper() if by_objects else metric}")
    ax.set_title("Grasp stability CNN: " + ("diversity at a fixed trial count" if by_objects
                                            else "accuracy vs. training data"))
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    return _finished(fig, path)
