"""One evaluation as typed configuration: robot, scenario, objects, policy, selection, loop, camera,
seeds and runs; YAML-loadable, with presets in the package.

    robot: panda                 # a built-in arm or an arm YAML file
    hand: ""                     # a shipped hand or a hand YAML file ("": the arm's)
    scenario: standard           # a shipped scenario or a scenario YAML file
    objects: ""                  # an object set or folder ("": the scenario's)
    object_units: m              # the folder's lengths: "m", or "mm" (scaled by 0.001)
    policy: cnn_rp
    selection: {staged: true, cnn_weights: models/grasp_cnn_all.pt, hold_weights: models/grasp_hold.pt}
    loop: {paper_loop: false, transit_ignores_objects: false, grasp_threshold: 0.0}
    depth_noise: false           # the depth camera's noise model
    top_grasp: false             # candidates straight down only (the paper's top-grasping variant)
    object_sleep: ""             # "on", "off" or "" (as the scenario says)
    max_attempts: 0              # attempts a run (0: as the scenario says)
    time_step: 0.0               # the physics step [s] (0: as the scenario says)
    grip_force: 0.0              # [N] a force-controlled grip (0: as the scenario says, by default a spring)
    sampler: ""                  # the candidates' sampler: uniform, gpg, mixed ("": as the scenario says)
    seed: 0                      # run k uses seed + k
    runs: 1

`--config NAME` takes a preset (`default`, today's default; `paper`, the paper's policy and loop
exactly), `--config FILE` a YAML file of these fields; a field it leaves out keeps its default.
"""

# No `from __future__ import annotations`: yaml_load_typed reads the dataclass field types.
import dataclasses as dc
from pathlib import Path

from pydrake.common.yaml import yaml_load_typed

from drake_grasp.policy.config import SelectionConfig
from drake_grasp.robot.config import MAX_GRIP_FORCE
from drake_grasp.robot.object_files import MESH_UNITS
from drake_grasp.robot.task import SAMPLERS
from drake_grasp.simulation.scenario import Scenario, load_scenario

PRESETS_DIR = Path(__file__).resolve().parent / "presets"
OBJECT_SLEEP = ("", "on", "off")


@dc.dataclass
class LoopConfig:
    """How the cell goes about its attempts beyond the policy's ranking."""

    paper_loop: bool = False  # the paper's loop: no failure memory, no early stop when nothing is reachable
    transit_ignores_objects: bool = False  # plan the transit against the robot and table only
    grasp_threshold: float = 0.0  # the best untried candidate's p_s * p_h is under it: "nothing graspable"
    # ends the run (0: off; only the policies that predict p_s stop)


@dc.dataclass
class EvaluationConfig:
    """What `simulate` runs (see the module's docstring); `seed` and `runs` choose the runs."""

    robot: str = "panda"
    hand: str = ""  # a shipped hand or a hand YAML file; "": the arm's
    scenario: str = "standard"
    objects: str = ""
    object_units: str = "m"
    policy: str = "cnn_rp"
    selection: SelectionConfig = dc.field(default_factory=SelectionConfig)
    loop: LoopConfig = dc.field(default_factory=LoopConfig)
    depth_noise: bool = False
    top_grasp: bool = False
    object_sleep: str = ""
    max_attempts: int = 0
    time_step: float = 0.0
    grip_force: float = 0.0  # [N] the hand grips force-controlled (`ControlConfig`); 0: the scenario's grip
    sampler: str = ""  # the candidates' sampler (`robot.task.SAMPLERS`); "": the scenario's
    gpg_stop_at_table: bool = False  # GPG's hand stops at the table (`SamplingConfig`); False: the scenario's
    seed: int = 0
    runs: int = 1

    def check(self) -> None:
        """ValueError naming a field out of its range."""
        self.selection.check()
        if self.object_sleep not in OBJECT_SLEEP:
            raise ValueError(f"object_sleep must be 'on', 'off' or '' (as the scenario says), got "
                             f"'{self.object_sleep}'")
        if not 0.0 <= self.grip_force <= MAX_GRIP_FORCE:
            raise ValueError(f"grip_force must be in [0, {MAX_GRIP_FORCE:g}] N (0: as the scenario says), "
                             f"got {self.grip_force}")
        if self.sampler and self.sampler not in SAMPLERS:
            raise ValueError(f"sampler must be one of {', '.join(SAMPLERS)} or '' (as the scenario says), "
                             f"got '{self.sampler}'")
        if self.max_attempts < 0 or self.time_step < 0.0 or self.runs < 1 or self.seed < 0:
            raise ValueError("max_attempts and time_step must be >= 0 (0: as the scenario says), runs >= 1, "
                             "seed >= 0")
        if not 0.0 <= self.loop.grasp_threshold < 1.0:
            raise ValueError(f"loop.grasp_threshold must be in [0, 1) (0: off), "
                             f"got {self.loop.grasp_threshold}")
        if self.loop.paper_loop and self.loop.grasp_threshold > 0:
            raise ValueError("the paper's loop has no early stop: leave loop.grasp_threshold at 0 with it")
        if self.object_units not in MESH_UNITS:
            raise ValueError(f"object_units must be one of {', '.join(MESH_UNITS)}, "
                             f"got '{self.object_units}'")
        if self.scenario == "single":
            raise ValueError("scenario 'single' is for data collection; choose a closed-loop scenario")

    def robot_spec(self):
        """The arm (`robot.arms.get_robot`) with this evaluation's hand."""
        from drake_grasp.robot.arms import get_robot

        return get_robot(self.robot, self.hand)

    @property
    def seeds(self) -> list[int]:
        return [self.seed + k for k in range(self.runs)]

    def load_scenario(self) -> Scenario:
        """The scenario with this evaluation's camera, sleep, attempts, step, grip, sampler and approach
        angles."""
        from drake_grasp.policy.scorers import policy_scenario

        scenario = policy_scenario(self.policy, load_scenario(self.scenario))
        if self.depth_noise:
            scenario = scenario.with_depth_noise()
        if self.object_sleep:
            scenario = scenario.with_object_sleep(self.object_sleep == "on")
        if self.max_attempts:
            scenario = dc.replace(scenario, max_attempts=self.max_attempts)
        if self.time_step:
            scenario = scenario.with_time_step(self.time_step)
        if self.grip_force:
            scenario = scenario.with_grip_force(self.grip_force)
        if self.sampler:
            scenario = scenario.with_sampler(self.sampler)
        if self.gpg_stop_at_table:
            scenario = dc.replace(scenario, sampling=dc.replace(scenario.sampling, gpg_stop_at_table=True))
        return scenario.with_gamma_deg([0.0, 0.0]) if self.top_grasp else scenario

    def object_set(self) -> str:
        return self.objects or load_scenario(self.scenario).object_set

    def experiment(self) -> dict:
        """The configuration without its seeds: what two reports must share to be one experiment."""
        fields = dc.asdict(self)
        del fields["seed"], fields["runs"]
        # Fields at the value they had before they existed stay out: older reports remain one experiment.
        if fields["object_units"] == "m":
            del fields["object_units"]
        if fields["hand"] == "":
            del fields["hand"]
        if fields["grip_force"] == 0.0:
            del fields["grip_force"]
        if fields["sampler"] == "":
            del fields["sampler"]
        if not fields["gpg_stop_at_table"]:
            del fields["gpg_stop_at_table"]
        if fields["loop"]["grasp_threshold"] == 0.0:
            del fields["loop"]["grasp_threshold"]
        if not fields["selection"]["any_hand"]:
            del fields["selection"]["any_hand"]
        if fields["selection"]["cnn_precision"] == "float32":
            del fields["selection"]["cnn_precision"]
        return fields


TABLE_SUFFIX = "_table"  # a preset of a table of evaluations (`load_table`), not of one


def preset_names() -> list[str]:
    """The evaluation presets."""
    return sorted(p.stem for p in PRESETS_DIR.glob("*.yaml") if not p.stem.endswith(TABLE_SUFFIX))


def table_names() -> list[str]:
    """The table presets (`experiments`)."""
    return sorted(p.stem for p in PRESETS_DIR.glob(f"*{TABLE_SUFFIX}.yaml"))


def _load_preset_or_file(name_or_path: str | Path, schema: type, what: str, presets: list[str]):
    """`schema` loaded from a preset of `presets` by name or from a YAML file; ValueError names what is
    wrong (`what`: "configuration" or "table")."""
    path = Path(name_or_path)
    if path.suffix not in (".yaml", ".yml"):
        if str(name_or_path) not in presets:
            raise ValueError(f"unknown {what} '{name_or_path}': not one of the presets {', '.join(presets)} "
                             "and not a YAML file")
        path = PRESETS_DIR / f"{name_or_path}.yaml"
    if not path.is_file():
        raise ValueError(f"{what} file not found: {path}")
    try:
        return yaml_load_typed(schema=schema, filename=str(path))
    except (RuntimeError, ValueError) as e:
        raise ValueError(f"invalid {what} {path}: {str(e).splitlines()[0]}") from None


def load_config(name_or_path: str | Path | None = None) -> EvaluationConfig:
    """A preset by name, a YAML file by path, or the defaults (None); ValueError names what is wrong."""
    config = (EvaluationConfig() if name_or_path is None
              else _load_preset_or_file(name_or_path, EvaluationConfig, "configuration", preset_names()))
    config.check()
    return config


@dc.dataclass
class TableEntry:
    """One entry of a table of evaluations: a scenario and a policy (straight-down grasps or not), and other
    stability CNN weights ("": the base's) and "nothing graspable" stop (0: the base's) than the base's."""

    scenario: str = "standard"
    policy: str = "cnn_rp"
    top_grasp: bool = False
    cnn_weights: str = ""
    grasp_threshold: float = 0.0


@dc.dataclass
class TableConfig:
    """A table of evaluations (`experiments`): each entry is `base` with its scenario and policy, `runs`
    runs each (`challenging_runs` in the challenging scene, 0: `runs`)."""

    base: EvaluationConfig = dc.field(default_factory=EvaluationConfig)
    entries: list[TableEntry] = dc.field(default_factory=list)
    runs: int = 30
    challenging_runs: int = 0

    def evaluations(self) -> list[EvaluationConfig]:
        """Each entry's configuration, with its runs."""
        out = []
        for entry in self.entries:
            slow = entry.scenario == "challenging" and self.challenging_runs
            runs = self.challenging_runs if slow else self.runs
            selection = (dc.replace(self.base.selection, cnn_weights=entry.cnn_weights) if entry.cnn_weights
                         else self.base.selection)
            loop = (dc.replace(self.base.loop, grasp_threshold=entry.grasp_threshold) if entry.grasp_threshold
                    else self.base.loop)
            out.append(dc.replace(self.base, scenario=entry.scenario, policy=entry.policy,
                                  top_grasp=entry.top_grasp, runs=runs, selection=selection, loop=loop))
        return out


def load_table(name_or_path: str | Path) -> TableConfig:
    """A table preset by name (`paper_table`) or a YAML file; ValueError names what is wrong."""
    table = _load_preset_or_file(name_or_path, TableConfig, "table", table_names())
    if not table.entries:
        raise ValueError(f"table {name_or_path} has no entries")
    for config in table.evaluations():
        config.check()
    return table
