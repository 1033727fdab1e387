"""A policy's own choices tried in physics: the closed loop's grasp choice, judged without the arm.

Ranking metrics on a data sampler's trials (`evaluate_cnn`) score every candidate alike; the closed loop
only ever executes a policy's first choice, among 500 uniform candidates backed off the table. Here each
seeded scene (`grasp_collection.build_scene`: 1 to N objects of an object set in the scenario's first
cluster, settled, observed by the scenario's camera) is ranked by one or more selection variants
(`SelectionConfig`s of the same policy) from the same candidates, and the top `top` candidates of each
are tried with the floating hand (`GraspTrialScene.run`: the task's motions and success rule). Variants
that choose the same candidate share its trial, so two variants differ only where their choices do: a
paired comparison, far less noisy than two closed-loop runs, which part ways after the first attempt.
What it leaves out is the arm: reachability enters through p_r only, planning never fails.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from dataclasses import dataclass

import numpy as np

from drake_grasp.policy.scorers import SelectionConfig
from drake_grasp.simulation.divergence import DIVERGED, is_divergence
from drake_grasp.stats import sign_test_p, wilson_ci95

DEFAULT_VARIANT = "default"


@dataclass(frozen=True)
class Variant:
    """A named way to select: the policy with this `SelectionConfig`."""

    name: str
    selection: SelectionConfig


def _field_value(field: dataclasses.Field, text: str):
    """`text` as the type of a `SelectionConfig` field ('none' for an optional one)."""
    kind = str(field.type)
    if text.lower() == "none" and "None" in kind:
        return None
    kind = kind.replace(" | None", "")
    if kind == "bool":
        if text.lower() not in ("true", "false", "1", "0"):
            raise ValueError(f"{field.name} takes true or false, got '{text}'")
        return text.lower() in ("true", "1")
    if kind == "int":
        return int(text)
    if kind == "float":
        return float(text)
    return text


def parse_variant(text: str) -> Variant:
    """`NAME` (the default selection) or `NAME=FIELD:VALUE[,FIELD:VALUE...]` with `SelectionConfig`
    fields, e.g. `cameras=cnn_weights:models/grasp_cnn_cameras.pt` or `paper=hold_weights:none`."""
    name, _, options = text.partition("=")
    if not name:
        raise ValueError(f"a variant needs a name: '{text}'")
    fields = {f.name: f for f in dataclasses.fields(SelectionConfig)}
    chosen = {}
    for option in filter(None, options.split(",")):
        key, sep, value = option.partition(":")
        if not sep or key not in fields:
            raise ValueError(f"variant '{name}': expected FIELD:VALUE with FIELD one of "
                             f"{', '.join(fields)}, got '{option}'")
        chosen[key] = _field_value(fields[key], value)
    return Variant(name, SelectionConfig(**chosen))


def scene_choices(scene_id: int, *, objects: str, scenario: str, seed: int, variants: list[Variant],
                  top: int, policy: str = "cnn_rp", robot: str = "panda", depth_noise: bool = False) -> dict:
    """Scene `scene_id` of the job: its objects, and for each variant its `top` choices with their
    predictions and the outcome of their trial (a JSON-ready record, see the module)."""
    from drake_grasp.datasets.grasp_collection import build_scene
    from drake_grasp.policy.sampling import approach_angle_deg
    from drake_grasp.policy.selector import rank_grasps

    models = _object_set(objects)
    scenario_used, scene, chosen, rng = build_scene(scene_id, models=models, scenario_arg=scenario, seed=seed,
                                                    depth_noise=depth_noise)
    record = {"scene": scene_id, "objects": [models[i].name for i in chosen], "points": 0, "choices": {}}
    try:
        scene.settle(rng)
        cloud = scene.observe()
    except RuntimeError as e:
        if not is_divergence(e):
            raise
        return record | {"error": f"the physics failed while the objects settled ({e})"}
    record["points"] = len(cloud)
    if len(cloud) == 0:
        return record
    trials: dict[bytes, dict] = {}
    for variant in variants:  # (each from the same random stream: the same 500 candidates)
        rng_candidates = np.random.default_rng([seed, scene_id])
        ranked = rank_grasps(cloud, _scorer(policy, robot, variant.selection),
                             num_candidates=scenario_used.num_candidates,
                             gamma_deg=tuple(scenario_used.gamma_deg), rng=rng_candidates)
        picks = []
        for k in range(min(top, len(ranked))):
            X_WG = ranked.X_WG[k]
            key = np.round(X_WG, 9).tobytes()
            if key not in trials:
                result = scene.run(X_WG)
                outcome = {"outcome": result.outcome.text, "rise": round(result.rise, 4),
                           "object": models[chosen[result.object_index]].name}
                trials[key] = {"trial": len(trials), **outcome}
            picks.append({
                "rank": k, **trials[key],
                "grasp_point": [round(float(v), 4) for v in X_WG[:3, 3]],
                "approach_angle_deg": round(float(approach_angle_deg(X_WG)), 1),
                "score": _rounded(ranked.scores[k]),
                **{name: _rounded(getattr(ranked, name)[k]) for name in ("p_r", "p_s", "p_h")},
            })
        record["choices"][variant.name] = picks
    record["trials"] = len(trials)
    return record


def _rounded(value: float) -> float | None:
    return None if np.isnan(value) else round(float(value), 4)


_OBJECT_SETS: dict[str, list] = {}
_SCORERS: dict[tuple, object] = {}


def _object_set(objects: str) -> list:
    """The object set, loaded once per worker process."""
    from drake_grasp.simulation.objects import load_object_set

    if objects not in _OBJECT_SETS:
        _OBJECT_SETS[objects] = load_object_set(objects)
    return _OBJECT_SETS[objects]


def _scorer(policy: str, robot: str, selection: SelectionConfig):
    """The policy's scorer with this selection, built once per worker process (the networks load once)."""
    from drake_grasp.policy.scorers import make_scorer
    from drake_grasp.robots import get_robot

    key = (policy, robot, selection)
    if key not in _SCORERS:
        _SCORERS[key] = make_scorer(policy, get_robot(robot), selection)
    return _SCORERS[key]


# -- the summary --------------------------------------------------------------------------------------
def _judged(pick: dict) -> bool:
    return pick["outcome"] != DIVERGED


def _same_trial(a: dict, b: dict) -> bool:
    """Whether two choices of one scene are one candidate (records before "trial" was stored: the same
    grasp point and approach angle)."""
    if "trial" in a and "trial" in b:
        return a["trial"] == b["trial"]
    return a["grasp_point"] == b["grasp_point"] and a["approach_angle_deg"] == b["approach_angle_deg"]


def summarize(records: list[dict], variants: list[str]) -> dict:
    """Per variant: its first choices' success rate (Wilson 95 %), all its top-k trials', the first
    choices' outcomes and the objects they failed on; each later variant paired with the first."""
    scenes = [r for r in records if r.get("choices")]
    out = {"scenes": len(records), "scenes_with_choices": len(scenes), "variants": {}, "paired": {}}
    for name in variants:
        firsts = [r["choices"][name][0] for r in scenes if _judged(r["choices"][name][0])]
        every = [p for r in scenes for p in r["choices"][name] if _judged(p)]
        wins = sum(p["outcome"] == "success" for p in firsts)
        lifted = sum(p["outcome"] == "success" for p in every)
        low, high = wilson_ci95(wins, len(firsts))
        failed = Counter((p["object"], p["outcome"]) for p in firsts if p["outcome"] != "success")
        out["variants"][name] = {
            "first_choices": len(firsts), "first_choice_success": wins,
            "first_choice_rate": round(wins / len(firsts), 4) if firsts else None,
            "ci95": [round(low, 4), round(high, 4)],
            "top_k_trials": len(every),
            "top_k_rate": round(lifted / len(every), 4) if every else None,
            "first_choice_outcomes": dict(Counter(p["outcome"] for p in firsts)),
            "first_choice_failures": [{"object": o, "outcome": f, "count": c}
                                      for (o, f), c in failed.most_common()],
        }
    base = variants[0]
    for name in variants[1:]:
        same = differ = wins = losses = 0
        for r in scenes:
            a, b = r["choices"][base][0], r["choices"][name][0]
            if not (_judged(a) and _judged(b)):
                continue
            if _same_trial(a, b):
                same += 1
                continue
            differ += 1
            won, lost = b["outcome"] == "success", a["outcome"] == "success"
            wins += won and not lost
            losses += lost and not won
        out["paired"][name] = {"against": base, "same_first_choice": same, "different_first_choice": differ,
                               "wins": wins, "losses": losses,
                               "sign_test_p": round(sign_test_p(wins, losses), 4)}
    return out


def summary_markdown(summary: dict, job: dict) -> str:
    """The summary as a Markdown report."""
    lines = [f"# The policy's choices in physics: {job['objects']}, scenario {job['scenario']}, "
             f"seed {job['seed']}" + (", noisy camera" if job.get("depth_noise") else ""), "",
             f"{summary['scenes_with_choices']} of {summary['scenes']} scenes with an object cloud; "
             f"policy {job['policy']}, robot {job['robot']}, top {job['top']} choices tried.", "",
             "| variant | first choice lifted | 95 % interval | top-k trials lifted "
             "| first choices' failures |",
             "|---|---|---|---|---|"]
    for name, v in summary["variants"].items():
        rate = "-" if v["first_choice_rate"] is None else f"{100 * v['first_choice_rate']:.1f} %"
        top_k = "-" if v["top_k_rate"] is None else f"{100 * v['top_k_rate']:.1f} % of {v['top_k_trials']}"
        failures = ", ".join(f"{k} {n}" for k, n in v["first_choice_outcomes"].items()
                             if k != "success") or "-"
        lines.append(f"| {name} | {v['first_choice_success']} of {v['first_choices']} ({rate}) | "
                     f"{100 * v['ci95'][0]:.1f}-{100 * v['ci95'][1]:.1f} % | {top_k} | {failures} |")
    if summary["paired"]:
        lines += ["", "Paired with the first variant (the same scenes and candidates): where the first "
                  "choices differ, the scenes each variant alone lifted.", "",
                  "| variant | against | same first choice | different | it alone lifted | the other alone "
                  "lifted | sign test p |", "|---|---|---|---|---|---|---|"]
        for name, p in summary["paired"].items():
            lines.append(f"| {name} | {p['against']} | {p['same_first_choice']} | "
                         f"{p['different_first_choice']} | {p['wins']} | {p['losses']} | "
                         f"{p['sign_test_p']:.3f} |")
    return "\n".join(lines) + "\n"
