"""Training VPG's push and grasp nets together, by VPG's self-supervised rewards, in our simulator.

Training runs in **rounds**. In round r, `episodes_per_round` episodes of the training
scene (the challenging scene's 30 blocks, other seeds than any evaluation's) are played
in worker processes by the nets of round r - 1 (`VpgPushScorer`, epsilon-greedy between the
primitives: VPG's exploration, annealed from `explore_start` to `explore_end`). Each
executed action becomes a transition: the heightmap it saw, the action (push or grasp,
cell, angle), its reward (1 for a grasp that lifted an object, `PUSH_REWARD` for a push
after which the heightmap changed, by VPG's rule, else 0; an episode's last push, with no
heightmap after it, by the cell's own judgement, an object moved 1 cm) and VPG's label: the
reward plus `DISCOUNT` times the best Q the playing nets saw in the next heightmap (0 where
none was taken: after the last action of an episode cut at `max_actions` too). Then the
nets take `steps_per_round` Huber-loss steps on the Q of executed actions, half of each
batch from the round's own transitions and half replayed from all rounds (VPG backpropagates
each new action and replays old ones).

Everything is resumable: each episode is a shard (`datasets.shards`) and each round's
nets a file in `nets/`, so a rerun continues where it stopped, on another machine too.
A planned action that the arm could not execute (no plan) counts, with reward 0.
"""

from __future__ import annotations

import dataclasses as dc
import functools
import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from torch import nn

from drake_grasp.datasets.shards import run_shards, shard_files, shard_index
from drake_grasp.policy.baselines.vpg import load_model as load_grasp_model
from drake_grasp.policy.baselines.vpg_push import (
    DISCOUNT,
    GRASP_REWARD,
    PUSH_REWARD,
    Q_MAX,
    VpgPushGraspNet,
    action_of,
    common_square,
    save_model,
    scene_changed,
)
from drake_grasp.robot.paths import model_path

HEIGHT_UNIT = 1e-4  # stored heightmaps are integer multiples of this [m]


@dc.dataclass(frozen=True)
class PushTrainingConfig:
    """VPG's training in our simulator (scaled to what a small machine does in hours)."""

    scenario: str = "challenging"
    objects: str = "primitives"
    robot: str = "panda"
    first_seed: int = 10_000  # episode k plays the scene of seed first_seed + k
    episodes_per_round: int = 2
    max_actions: int = 20  # per episode
    explore_start: float = 0.5
    explore_end: float = 0.1
    explore_rounds: int = 40  # the exploration anneals linearly over this many rounds
    steps_per_round: int = 40
    batch_size: int = 8
    lr: float = 1e-4
    width: int = 32
    # The grasp net starts from VPG's grasp-only net, named as `robot.paths.model_path` reads it ("": from
    # scratch).
    init_grasp: str = "models/vpg.pt"
    seed: int = 0

    def explore(self, round_index: int) -> float:
        f = min(round_index / max(self.explore_rounds, 1), 1.0)
        return self.explore_start + f * (self.explore_end - self.explore_start)


def initial_nets(config: PushTrainingConfig) -> VpgPushGraspNet:
    """Round 0's nets: the grasp net from `init_grasp`; the push net new, its Q near `PUSH_REWARD`."""
    torch.manual_seed(config.seed)
    model = VpgPushGraspNet(config.width)
    if config.init_grasp:
        grasp, _ = load_grasp_model(model_path(config.init_grasp))
        if grasp.width != config.width:
            raise ValueError(f"{config.init_grasp} is {grasp.width} wide, the nets {config.width}")
        model.grasp.load_state_dict(grasp.state_dict())
    with torch.no_grad():
        model.push.head[-1].bias.fill_(float(np.log(PUSH_REWARD / (Q_MAX - PUSH_REWARD))))
    return model


# -- playing ---------------------------------------------------------------------------------
def play_episode(k: int, *, config: PushTrainingConfig, nets_dir: Path) -> dict[str, np.ndarray]:
    """Episode k (of round k // episodes_per_round) played by the previous round's nets, as arrays."""
    from drake_grasp.cell.episode import run_episode
    from drake_grasp.evaluation.config import EvaluationConfig
    from drake_grasp.evaluation.runs import executive_config
    from drake_grasp.policy.scorers import VpgPushScorer
    from drake_grasp.simulation.objects import load_object_set

    torch.set_num_threads(1)
    round_index = k // config.episodes_per_round
    evaluation = EvaluationConfig(robot=config.robot, scenario=config.scenario, objects=config.objects,
                                  policy="vpg_push", max_attempts=config.max_actions)
    observations: list = []
    scorer = VpgPushScorer(nets_path(nets_dir, round_index - 1), explore=config.explore(round_index),
                           observations=observations)
    entries: list[dict] = []
    robot = evaluation.robot_spec()
    result = run_episode(robot=robot, scenario=evaluation.load_scenario(), scorer=scorer,
                         object_models=load_object_set(evaluation.object_set()), seed=config.first_seed + k,
                         cell=executive_config(evaluation), on_attempt=lambda _, entry: entries.append(entry))
    del result  # what the episode did is in its entries
    return transitions(observations, entries)


def _acted_on(observations: list, start: int, entry: dict) -> tuple[int, int]:
    """(observation, candidate) indices, the observation at or after `start`, of what the entry executed."""
    point = np.asarray(entry["grasp_point"])
    push = bool(entry.get("push", False))
    for n in range(start, len(observations)):
        o = observations[n]
        near = np.abs(np.round(o.X_WG[:, :3, 3], 4) - point).max(axis=1) < 1e-6
        match = np.flatnonzero(near & (o.push == push))
        if len(match):
            return n, int(match[0])
    raise ValueError(f"an executed action at {point.tolist()} matches no candidate VPG offered")


def transitions(observations: list, entries: list[dict]) -> dict[str, np.ndarray]:
    """An episode's transitions: the heightmaps (padded about their centre to the episode's largest
    square), actions (push, i, j, k), rewards and VPG's labels."""
    acted, start = [], 0
    for entry in entries:
        n, c = _acted_on(observations, start, entry)
        acted.append((n, c))
        start = n + 1
    if not acted:
        return {"heights": np.zeros((0, 1, 1), np.uint16), "actions": np.zeros((0, 4), np.int16),
                "reward": np.zeros(0, np.float32), "label": np.zeros(0, np.float32)}
    seen = [observations[n] for n, _ in acted]
    cells = max(o.config.cells for o in seen)
    heights, actions = [], []
    for o, (_, c) in zip(seen, acted, strict=True):
        pad = (cells - o.config.cells) // 2
        heights.append(np.pad(o.heights, pad))
        a = action_of(o.X_WG[c], bool(o.push[c]), o.config)
        actions.append((a.push, a.i + pad, a.j + pad, a.k))
    reward = np.zeros(len(seen), np.float32)
    label = np.zeros(len(seen), np.float32)
    for t, entry in enumerate(entries):
        if not entry.get("push", False):
            reward[t] = GRASP_REWARD if entry["success"] else 0.0
        elif t + 1 < len(seen):
            smallest = min(seen[t].config.cells, seen[t + 1].config.cells)
            reward[t] = PUSH_REWARD * scene_changed(common_square(heights[t], smallest),
                                                    common_square(heights[t + 1], smallest))
        else:  # the episode's last action: no next heightmap, the cell's own judgement (an object moved)
            reward[t] = PUSH_REWARD * bool(entry["success"])
        # VPG's label: the reward and the discounted value of the next state, as the playing nets saw it.
        following = acted[t][0] + 1
        next_q = observations[following].best_q if following < len(observations) else 0.0
        label[t] = reward[t] + DISCOUNT * next_q
    return {"heights": np.round(np.stack(heights) / HEIGHT_UNIT).astype(np.uint16),
            "actions": np.array(actions, np.int16), "reward": reward, "label": label}


# -- learning --------------------------------------------------------------------------------
Step = tuple[dict, int]  # (an episode's arrays, a transition's index in it)


def nets_path(nets_dir: Path, round_index: int) -> Path:
    """Round r's nets (r = -1: the initial nets)."""
    return nets_dir / ("initial.pt" if round_index < 0 else f"round_{round_index:04d}.pt")


def load_episodes(episodes_dir: Path, files: list[Path] | None = None) -> list[dict[str, np.ndarray]]:
    """Each episode shard's arrays, in shard order (maps differ in size between episodes)."""
    out = []
    for f in shard_files(episodes_dir) if files is None else files:
        with np.load(f) as data:
            out.append({key: data[key] for key in data.files})
    return out


def steps_of(episodes: list[dict[str, np.ndarray]]) -> list[Step]:
    return [(e, t) for e in episodes for t in range(len(e["reward"]))]


def train_round(model: VpgPushGraspNet, new: list[Step], replay: list[Step], config: PushTrainingConfig,
                rng: np.random.Generator) -> float:
    """`steps_per_round` Adam steps on executed actions' Q (Huber loss to VPG's labels), half of each batch
    from `new` and half from `replay`; the mean loss."""
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=2e-5)
    loss_fn = nn.SmoothL1Loss()
    model.train()
    losses = []
    half = max(config.batch_size // 2, 1)
    for _ in range(config.steps_per_round):
        batch = [new[i] for i in rng.integers(len(new), size=half)]
        batch += [replay[i] for i in rng.integers(len(replay), size=config.batch_size - half)]
        q = []
        for episode, t in batch:  # maps differ in size between episodes: one transition at a time
            heights = torch.from_numpy(episode["heights"][t].astype(np.float32) * HEIGHT_UNIT)[None]
            a = torch.as_tensor(episode["actions"][t], dtype=torch.long)[None]
            q.append(model.executed_q(heights, a[:, 1:], a[:, 0].bool()))
        labels = torch.tensor([float(episode["label"][t]) for episode, t in batch])
        loss = loss_fn(torch.cat(q), labels)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    model.eval()
    return float(np.mean(losses))


def round_summary(round_index: int, episodes: list[dict[str, np.ndarray]], loss: float | None,
                  config: PushTrainingConfig) -> dict:
    """What round r's episodes did, and the loss of the steps after them."""
    actions = np.concatenate([e["actions"] for e in episodes]) if episodes else np.zeros((0, 4))
    reward = np.concatenate([e["reward"] for e in episodes]) if episodes else np.zeros(0)
    push = actions[:, 0].astype(bool)
    grasps = int((~push).sum())
    return {"round": round_index, "explore": round(config.explore(round_index), 4),
            "actions": int(len(reward)), "grasps": grasps, "grasp_successes": int((reward[~push] > 0).sum()),
            "pushes": int(push.sum()), "pushes_changed": int((reward[push] > 0).sum()),
            "loss": None if loss is None else round(loss, 5)}


def _load_nets(path: Path) -> tuple[VpgPushGraspNet, dict]:
    from drake_grasp.policy.baselines.vpg_push import load_model

    model, record = load_model(path)
    return model, record.get("card", {})


def _save_atomically(model: VpgPushGraspNet, path: Path, *, card: dict) -> None:
    """The nets at `path`, written whole or not at all (a round's nets mark it done)."""
    partial = path.with_suffix(path.suffix + ".partial")
    save_model(model, partial, card=card)
    partial.replace(path)


def _learn_round(config: PushTrainingConfig, r: int, episodes_dir: Path, nets_dir: Path, workers: int,
                 ray_address: str | None) -> dict:
    """Round r: its episodes (the missing ones), its steps, its nets saved with the round's summary."""
    per = config.episodes_per_round
    t0 = time.perf_counter()
    run_shards(functools.partial(play_episode, config=config, nets_dir=nets_dir), num_shards=(r + 1) * per,
               out_dir=episodes_dir, workers=workers, ray_address=ray_address, unit="episodes",
               progress_stats=lambda arrays: (1, 0))
    played = time.perf_counter() - t0
    files = shard_files(episodes_dir)[:(r + 1) * per]
    episodes = load_episodes(episodes_dir, files)
    this_round = [e for f, e in zip(files, episodes, strict=True) if shard_index(f) // per == r]
    model, _ = _load_nets(nets_path(nets_dir, r - 1))
    torch.manual_seed(config.seed + r)
    new, replay = steps_of(this_round), steps_of(episodes)
    loss = train_round(model, new or replay, replay, config, np.random.default_rng([config.seed, r])) \
        if replay else None  # (no action played yet: no step)
    row = round_summary(r, this_round, loss, config)
    row |= {"play_seconds": round(played, 1), "learn_seconds": round(time.perf_counter() - t0 - played, 1)}
    _save_atomically(model, nets_path(nets_dir, r), card=row)
    return row


def train_vpg_push(config: PushTrainingConfig, *, data_dir: Path, rounds: int, workers: int = 0,
                   ray_address: str | None = None, log: Callable[[str], None] = print,
                   ) -> tuple[VpgPushGraspNet, list[dict]]:
    """Plays and learns `rounds` rounds into `data_dir` (continuing what is there); the last round's
    nets and every round's summary."""
    episodes_dir, nets_dir = data_dir / "episodes", data_dir / "nets"
    nets_dir.mkdir(parents=True, exist_ok=True)
    settings = data_dir / "training.json"
    if settings.exists():
        held, asked = json.loads(settings.read_text()), dc.asdict(config)
        differing = sorted(key for key in held.keys() | asked.keys() if held.get(key) != asked.get(key))
        if differing:
            raise ValueError(f"{data_dir} holds a training with other settings (its {', '.join(differing)} "
                             f"in {settings}); use another folder or the same settings")
    else:
        settings.write_text(json.dumps(dc.asdict(config), indent=1))
    if not nets_path(nets_dir, -1).exists():
        _save_atomically(initial_nets(config), nets_path(nets_dir, -1), card={"round": -1})
    history = []
    for r in range(rounds):
        path = nets_path(nets_dir, r)
        row = _load_nets(path)[1] if path.exists() else _learn_round(config, r, episodes_dir, nets_dir,
                                                                       workers, ray_address)
        history.append(row)
        log(f"round {r}: {row['actions']} actions, grasps {row['grasp_successes']}/{row['grasps']}, "
            f"pushes that changed the scene {row['pushes_changed']}/{row['pushes']}, loss {row['loss']}, "
            f"explore {row['explore']:.2f}")
    return _load_nets(nets_path(nets_dir, rounds - 1))[0], history


def plot_training(history: list[dict], path: Path) -> None:
    """The training's curves per round: grasp success, the share of pushes, pushes that changed the scene,
    the loss."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rounds = [row["round"] for row in history]

    def rate(num: str, den: str) -> list[float]:
        return [row[num] / row[den] if row[den] else np.nan for row in history]

    fig, (ax, loss_ax) = plt.subplots(1, 2, figsize=(10, 3.6))
    ax.plot(rounds, rate("grasp_successes", "grasps"), label="grasp success")
    ax.plot(rounds, rate("pushes", "actions"), label="share of pushes")
    ax.plot(rounds, rate("pushes_changed", "pushes"), label="pushes that changed the scene")
    ax.plot(rounds, [row["explore"] for row in history], ":", color="grey", label="exploration")
    ax.set(xlabel="round", ylim=(0, 1.02), title="VPG with pushing: training episodes")
    ax.legend(fontsize=8)
    loss_ax.plot(rounds, [np.nan if row["loss"] is None else row["loss"] for row in history])
    loss_ax.set(xlabel="round", ylabel="Huber loss", title="Q at the executed action")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def vpg_push_card(config: PushTrainingConfig, history: list[dict], *, data_dir: Path, command: str) -> dict:
    """The model card of nets trained by `train_vpg_push` over `history`'s rounds (what the nets do now:
    the last quarter of the rounds)."""
    totals = {key: sum(row[key] for row in history)
              for key in ("actions", "grasps", "grasp_successes", "pushes", "pushes_changed")}
    last = history[-max(len(history) // 4, 1):]
    return {
        "model": "VPG (Zeng et al. 2018) with pushing: push and grasp nets (small fully convolutional nets "
                 "on 2 mm heightmaps, 16 push directions over a full turn, 16 jaw angles over half a turn), "
                 "Q = 2 sigmoid, Huber loss at the executed action, VPG's rewards and discount 0.5",
        "data": {"folder": str(data_dir), "settings": dc.asdict(config), **totals},
        "command": command,
        "seed": config.seed, "rounds": len(history),
        "training_metrics": {
            "rounds": len(last),
            "grasp_success": sum(r["grasp_successes"] for r in last) / max(sum(r["grasps"] for r in last), 1),
            "push_share": sum(r["pushes"] for r in last) / max(sum(r["actions"] for r in last), 1),
            "pushes_changed": sum(r["pushes_changed"] for r in last) / max(sum(r["pushes"] for r in last), 1),
        },
        "train_seconds": round(sum(r["play_seconds"] + r["learn_seconds"] for r in history), 1),  # wall
        "history": history,
    }
