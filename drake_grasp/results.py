"""The closed loop's reports read back: tables and charts in the style of the paper's Fig. 7 and Table I.

A report is the JSON that `python -m drake_grasp.simulate --report` writes: one
(robot, scenario, object set, policy) cell with its runs. Rates are means over runs
with a 95 % confidence interval (Student's t over the runs), as the paper reports
them; the paper's own number stands beside ours where the paper gives one.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drake_grasp.stats import mean_ci95

RATES = ("grasp_success_rate", "completion_rate", "planning_success_rate")
RATE_NAMES = {"grasp_success_rate": "grasp success", "completion_rate": "completion",
              "planning_success_rate": "planning success"}
POLICY_NAMES = {"rand": "RAND", "cnn": "3DCNN", "rp": "RP only", "cnn_rp": "OURS (CNN x RP)",
                "gpd1c": "GPD1c", "gpd": "GPD", "vpg": "VPG"}
POLICY_ORDER = ("rand", "gpd1c", "gpd", "vpg", "rp", "cnn", "cnn_rp")
SCENARIO_ORDER = ("standard", "challenging", "ablation", "beyond_reach")

# The paper's simulated results (UR5 in V-REP, 30 runs a cell), where the text gives the number:
# Table I (ablation) in full; of Fig. 7 only what the text states (the figure's bars are not tabulated).
PAPER = {
    ("ablation", "rand"): {"grasp_success_rate": 0.1333, "planning_success_rate": 0.2667},
    ("ablation", "cnn"): {"grasp_success_rate": 0.3267, "planning_success_rate": 0.3733},
    ("ablation", "cnn_rp"): {"grasp_success_rate": 0.8267, "planning_success_rate": 0.9600},
    ("challenging", "cnn_rp"): {"grasp_success_rate": 0.715, "completion_rate": 1.0},
    ("standard", "cnn_rp"): {"completion_rate": 1.0},
}


@dataclass(frozen=True)
class Cell:
    """One report: a (robot, scenario, objects, policy) cell and its per-run rates."""

    robot: str
    scenario: str
    objects: str
    policy: str
    runs: dict[str, np.ndarray]  # rate -> (runs,)
    path: Path
    top_grasp: bool = False  # candidates approached straight down only (the paper's "top grasping")
    noisy_camera: bool = False  # the depth camera's noise model was on

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
    def label(self) -> str:
        label = self.scenario if self.objects == "primitives" else f"{self.scenario} ({self.objects})"
        variants = {", top grasps": self.top_grasp, ", noisy camera": self.noisy_camera}
        return label + "".join(name for name, on in variants.items() if on)


def read_report(path: str | Path) -> Cell | None:
    """The cell of a `simulate` report; None for another kind of JSON."""
    path = Path(path)
    data = json.loads(path.read_text())
    if not {"robot", "scenario", "policy", "runs"} <= data.keys():
        return None
    runs = {rate: np.array([r[rate] for r in data["runs"]], dtype=float) for rate in RATES}
    objects = data.get("objects") or "primitives"
    return Cell(data["robot"], data["scenario"], objects, data["policy"], runs, path,
                bool(data.get("top_grasp")), "depth_noise" in data)


def load_reports(folder: str | Path, robot: str | None = None) -> list[Cell]:
    """Every `simulate` report in a folder (not its subfolders), optionally of one robot, in table order."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"no report folder at {folder}")
    cells = [c for p in sorted(folder.glob("*.json")) if (c := read_report(p)) is not None]
    cells = [c for c in cells if robot is None or c.robot == robot]
    return sorted(cells, key=_order)


def _order(cell: Cell) -> tuple:
    scenario = SCENARIO_ORDER.index(cell.scenario) if cell.scenario in SCENARIO_ORDER else len(SCENARIO_ORDER)
    policy = POLICY_ORDER.index(cell.policy) if cell.policy in POLICY_ORDER else len(POLICY_ORDER)
    variant = (cell.objects != "primitives", cell.objects, cell.top_grasp, cell.noisy_camera)
    return cell.robot, scenario, *variant, policy


def _percent(mean: float, half: float) -> str:
    return f"{100 * mean:.1f}" + ("" if np.isnan(half) else f" ± {100 * half:.1f}")


def markdown_table(cells: list[Cell]) -> str:
    """Robot, scenario, policy, runs and each rate (mean ± 95 % CI, %), the paper's number in brackets."""
    head = ["robot", "scenario", "policy", "runs", *(RATE_NAMES[r] + " %" for r in RATES)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for c in cells:
        values = []
        for rate in RATES:
            text = _percent(*c.rate(rate))
            if (paper := c.paper(rate)) is not None:
                text += f" [paper {100 * paper:.1f}]"
            values.append(text)
        row = [c.robot, c.label, POLICY_NAMES.get(c.policy, c.policy), str(c.num_runs), *values]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def _grouped_bars(ax, cells: list[Cell], groups: list[str], rate: str) -> None:
    """Bars per group (x) and policy (colour), with 95 % intervals; the paper's numbers as black diamonds."""
    policies = [p for p in POLICY_ORDER if any(c.policy == p for c in cells)]
    policies += sorted({c.policy for c in cells} - set(policies))
    width = 0.8 / max(len(policies), 1)
    paper_drawn = False
    for j, policy in enumerate(policies):
        for i, group in enumerate(groups):
            cell = next((c for c in cells if c.policy == policy and c.label == group), None)
            if cell is None:
                continue
            x = i - 0.4 + width * (j + 0.5)
            mean, half = cell.rate(rate)
            error = None if np.isnan(half) else 100 * half
            ax.bar(x, 100 * mean, width, color=f"C{j}", yerr=error, capsize=3,
                   label=POLICY_NAMES.get(policy, policy) if i == 0 else None)
            ax.text(x, 2, f"n={cell.num_runs}", ha="center", fontsize=7, rotation=90, color="white")
            if (paper := cell.paper(rate)) is not None:
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


def plot_success_and_completion(cells: list[Cell], path: str | Path | None = None):
    """Paper Fig. 7: grasp success (top) and completion (bottom) per scenario and policy; the figure."""
    import matplotlib.pyplot as plt

    cells = [c for c in cells if c.scenario != "ablation"]
    groups = list(dict.fromkeys(c.label for c in cells))
    fig, axes = plt.subplots(2, 1, figsize=(3 + 2.2 * len(groups), 7), sharex=True)
    for ax, rate in zip(axes, ("grasp_success_rate", "completion_rate"), strict=True):
        _grouped_bars(ax, cells, groups, rate)
    robots = sorted({c.robot for c in cells})
    axes[0].set_title(f"Closed-loop grasping in simulation ({', '.join(robots)}); mean over runs, 95 % CI",
                      fontsize=10)
    return _finished(fig, path)


def plot_ablation(cells: list[Cell], path: str | Path | None = None):
    """Paper Table I as bars: grasp and planning success per policy in the ablation scene."""
    import matplotlib.pyplot as plt

    cells = [c for c in cells if c.scenario == "ablation"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, rate in zip(axes, ("grasp_success_rate", "planning_success_rate"), strict=True):
        _grouped_bars(ax, cells, ["ablation"], rate)
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


def cut_at_grasp_threshold(run: dict, threshold: float) -> dict:
    """A report's run as it would have gone with `CellConfig.grasp_threshold` = `threshold`.

    Exact, not an estimate: the executive tries the best untried candidate first and the stop ends
    the run at the first attempt whose candidate scores under the threshold, so the run with the
    stop is the logged run up to that attempt (same seed, same physics) and nothing after it.
    Returns the attempts, successes, the three rates (as `EpisodeResult` defines them) and whether
    the stop ended the run.
    """
    from drake_grasp.policy.episode import EpisodeResult  # (here: the table commands need no physics)

    log = run["attempt_log"]
    kept = next((k for k, a in enumerate(log) if not (a["score"] is not None and a["score"] >= threshold)),
                len(log)) if threshold > 0 else len(log)
    successes = sum(bool(a["success"]) for a in log[:kept])
    cut = EpisodeResult(seed=run["seed"], num_objects=run["num_objects"], attempts=kept, successes=successes,
                        plans_tried=kept, plans_succeeded=sum(bool(a["planned"]) for a in log[:kept]),
                        objects_grasped=successes)
    return {"attempts": kept, "successes": successes, "stopped": kept < len(log),
            "grasp_success_rate": cut.grasp_success_rate, "completion_rate": cut.completion_rate,
            "planning_success_rate": cut.planning_success_rate}
