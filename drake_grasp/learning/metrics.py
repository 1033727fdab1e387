"""Binary classification metrics for the learned predictors (pure numpy)."""

from __future__ import annotations

import numpy as np


def auroc(labels: np.ndarray, scores: np.ndarray) -> float:
    """Area under the ROC curve: the chance a random positive outscores a random negative."""
    labels = np.asarray(labels).astype(bool)
    n_pos, n_neg = labels.sum(), (~labels).sum()
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    order = np.argsort(scores, kind="mergesort")
    ranks = np.empty(len(scores))
    sorted_scores = np.asarray(scores)[order]
    # Average ranks over ties (1-based).
    _, first, counts = np.unique(sorted_scores, return_index=True, return_counts=True)
    tie_ranks = first + (counts + 1) / 2
    ranks[order] = np.repeat(tie_ranks, counts)
    return float((ranks[labels].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def expected_calibration_error(labels: np.ndarray, probs: np.ndarray, bins: int = 10) -> float:
    """Mean |accuracy - confidence| over equal-width probability bins, weighted by bin size."""
    labels, probs = np.asarray(labels, float), np.asarray(probs, float)
    edges = np.linspace(0, 1, bins + 1)
    which = np.clip(np.digitize(probs, edges[1:-1]), 0, bins - 1)
    error = 0.0
    for b in range(bins):
        mask = which == b
        if mask.any():
            error += mask.mean() * abs(labels[mask].mean() - probs[mask].mean())
    return float(error)


def classification_metrics(labels: np.ndarray, probs: np.ndarray, threshold: float = 0.5) -> dict:
    labels = np.asarray(labels).astype(bool)
    predicted = np.asarray(probs) >= threshold
    tp = int((predicted & labels).sum())
    fp = int((predicted & ~labels).sum())
    fn = int((~predicted & labels).sum())
    return {
        "n": int(len(labels)),
        "positive_rate": float(labels.mean()) if len(labels) else float("nan"),
        "accuracy": float((predicted == labels).mean()),
        "precision": tp / (tp + fp) if tp + fp else float("nan"),
        "recall": tp / (tp + fn) if tp + fn else float("nan"),
        "auroc": auroc(labels, probs),
        "ece": expected_calibration_error(labels, probs),
    }


def top_fraction_success(labels: np.ndarray, probs: np.ndarray, fraction: float = 0.1) -> float:
    """The success rate of the best-scored `fraction` of the candidates (at least one): what a robot
    that tries the top of the ranking would see."""
    labels, probs = np.asarray(labels, float), np.asarray(probs, float)
    if len(labels) == 0:
        return float("nan")
    top = np.argsort(-probs, kind="stable")[:max(1, round(fraction * len(labels)))]
    return float(labels[top].mean())


def best_per_scene_success(labels: np.ndarray, probs: np.ndarray, scenes: np.ndarray) -> float:
    """The success rate of each scene's best-scored candidate, over scenes: what a policy that
    executes its top choice once per scene would see."""
    labels, probs, scenes = np.asarray(labels, float), np.asarray(probs, float), np.asarray(scenes)
    if len(labels) == 0:
        return float("nan")
    order = np.lexsort((-probs, scenes))  # by scene, best first within each (ties: the first trial)
    first = np.r_[True, scenes[order][1:] != scenes[order][:-1]]
    return float(labels[order][first].mean())


def per_group_metrics(labels: np.ndarray, probs: np.ndarray, groups: np.ndarray,
                      scenes: np.ndarray | None = None) -> dict[str, dict]:
    """{group: {n, positive_rate, auroc, top10_success[, best_per_scene]}} of each group (an object's
    trials); `best_per_scene` where the trials' `scenes` are given."""
    labels, probs, groups = np.asarray(labels), np.asarray(probs), np.asarray(groups)
    scenes = None if scenes is None else np.asarray(scenes)
    result = {}
    for g in sorted(set(groups.tolist())):
        rows = groups == g
        metrics = {"n": int(rows.sum()), "positive_rate": float(labels[rows].mean()),
                   "auroc": auroc(labels[rows], probs[rows]),
                   "top10_success": top_fraction_success(labels[rows], probs[rows])}
        if scenes is not None:
            metrics["best_per_scene"] = best_per_scene_success(labels[rows], probs[rows], scenes[rows])
        result[str(g)] = metrics
    return result
