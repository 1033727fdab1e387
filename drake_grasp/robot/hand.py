"""The parallel-jaw hand, described by a YAML file like an arm, and the grasp-frame convention.

Grasp frame G: origin at the grasp point on the object surface, +z the approach
direction (pointing into the object), +y the finger closing direction. The hand
frame H is the hand's base link frame, at the arm's flange, with the same axes: +z out of
the palm, fingers sliding along +-y. The hand is placed so that its TCP lies `grasp_depth`
beyond the grasp point along the approach axis; `X_GH` is that one constant, used by
data collection, selection and execution alike. The same hand is mounted on every
arm, so the stability CNN is robot-independent and only the RP is per robot; data and
models record the hand's `fingerprint`, and one made with another hand is refused.

A hand file (`--hand FILE.yaml` wherever `--robot` goes, or `hand:` in an arm YAML):

    name: franka
    model: ../hand.sdf               # URDF or SDF, relative to this file
    package_path: []                 # optional: folders that hold the packages package:// names
    base_link: hand                  # the body on the flange (the model's root)
    frame_xyz: [0.0, 0.0, 0.0]       # the hand frame H in the base link's frame (default: the base link's)
    frame_rpy_deg: [0.0, 0.0, 0.0]
    fingers: [left_finger, right_finger]     # the two bodies that touch the object
    driven_joint: left_finger_joint  # the actuated joint the hand command sets
    coupled_joints: [right_finger_joint]     # joints that follow it 1:1 (none when the file has mimic tags)
    open_position: 0.04              # the driven joint's command, open [m or rad]
    closed_position: 0.0             # ... closed (the force limit decides the grip; either side of open)
    closed_on_nothing: 0.002         # the driven joint past this toward closed: the jaws met nothing
    grip_force: 40.0                 # the driven joint's effort limit [N or N m]
    stroke: 0.08                     # the jaws' opening, open [m]
    tcp_depth: 0.1034                # flange to TCP along +z_H [m]
    palm_depth: 0.0584               # flange to the finger base along +z_H [m]
    palm_size: [0.063, 0.204]        # the palm box along x_H, y_H [m]
    finger_length: 0.055             # finger base to fingertip [m]
    finger_size: [0.02, 0.012]       # a finger pad box along x_H, y_H [m]
    grasp_depth: 0.01                # the TCP beyond the grasp point [m]
    cnn_weights: ""                  # optional: this hand's stability CNN and hold predictor (relative to
    hold_weights: ""                 # this file; "none": no hold predictor), the policies' defaults with it

The policy reasons about the hand as these boxes (a palm and two fingers, open at the
stroke); the simulator uses the model file, its collision geometry made rigid hydroelastic where the
file declares no Drake contact (as makers' URDFs do; the fingerprint counts those geometries). A URDF
is made ready for Drake as an arm's is (`robot.model_files.prepare_hand_model`: `package://` paths
resolved, STL and DAE meshes made OBJ, ROS transmissions gone) and its `<mimic>` joints follow the
driven one. A file whose model does not parse, names a link or joint the model lacks, or gives sizes
that cannot be: one-line ValueErrors.
"""

# No `from __future__ import annotations`: yaml_load_typed reads the dataclass field types.
import dataclasses as dc
import functools
import hashlib
import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drake_grasp.robot.paths import SDF_DIR

if TYPE_CHECKING:  # (imported where used: reading data and model cards needs no Drake)
    from pydrake.math import RigidTransform

HANDS_DIR = SDF_DIR / "hands"
DEFAULT_HAND = "franka"


@dc.dataclass
class HandConfig:
    """A hand file's fields (see the module docstring)."""

    name: str = ""
    model: str = ""
    package_path: list[str] = dc.field(default_factory=list)
    base_link: str = ""
    frame_xyz: list[float] = dc.field(default_factory=lambda: [0.0, 0.0, 0.0])
    frame_rpy_deg: list[float] = dc.field(default_factory=lambda: [0.0, 0.0, 0.0])
    fingers: list[str] = dc.field(default_factory=list)
    driven_joint: str = ""
    coupled_joints: list[str] = dc.field(default_factory=list)
    open_position: float = float("nan")
    closed_position: float = float("nan")
    closed_on_nothing: float = float("nan")
    grip_force: float = float("nan")
    stroke: float = float("nan")
    tcp_depth: float = float("nan")
    palm_depth: float = float("nan")
    palm_size: list[float] = dc.field(default_factory=list)
    finger_length: float = float("nan")
    finger_size: list[float] = dc.field(default_factory=list)
    grasp_depth: float = 0.01
    cnn_weights: str = ""
    hold_weights: str = ""


@dc.dataclass(frozen=True)
class HandSpec:
    """Everything the simulator, the planner and the policy need to know about one hand."""

    name: str
    model_url: str  # the model file Drake parses (a URDF's prepared copy)
    base_link: str
    fingers: tuple[str, str]
    driven_joint: str
    coupled_joints: tuple[str, ...]
    open_position: float
    closed_position: float
    closed_on_nothing: float
    grip_force: float  # the driven joint's effort limit [N or N m]
    stroke: float  # [m]
    tcp_depth: float
    palm_depth: float
    palm_size: tuple[float, float]
    finger_length: float
    finger_size: tuple[float, float]
    grasp_depth: float
    # The model's mimic joints that follow the driven one: (joint, multiplier, offset), read from the file
    mimics: tuple[tuple[str, float, float], ...] = ()
    frame_xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)  # H in the base link's frame
    frame_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    source: str = ""  # what get_hand takes to make this spec again (a name or a YAML path)
    model_file: str = ""  # the user's model file, named in messages (default: model_url)
    cnn_weights: str = ""  # this hand's stability CNN ("": the policies' default, the Franka hand's)
    hold_weights: str = ""  # its hold predictor ("none": none; "": the default)
    # How many of the model's collision geometries name no hydroelastic contact and are simulated as the
    # project's rigid hydroelastic ones (`contact_model.fill_hand_contact`); part of the fingerprint
    contact_filled: int = 0

    @property
    def max_half_opening(self) -> float:
        """Each finger's travel from the centre, open [m]."""
        return self.stroke / 2

    @property
    def tcp_depth_to_tip(self) -> float:
        """The fingertips beyond the TCP along +z_H [m]."""
        return self.palm_depth + self.finger_length - self.tcp_depth

    @property
    def tip_beyond_grasp(self) -> float:
        """The fingertips beyond the grasp point along +z_G [m]."""
        return self.grasp_depth + self.tcp_depth_to_tip

    @property
    def joint_per_metre(self) -> float:
        """The driven joint's travel per metre of one finger's (1 for a prismatic finger's joint)."""
        return abs(self.open_position - self.closed_position) / self.max_half_opening

    def jaws_met(self, position: float) -> bool:
        """Whether the driven joint at `position` is past `closed_on_nothing` toward closed."""
        if self.closed_position < self.open_position:
            return position < self.closed_on_nothing
        return position > self.closed_on_nothing

    @property
    def X_BH(self) -> "RigidTransform":
        """The hand frame H in the base link's frame B."""
        from pydrake.math import RigidTransform, RollPitchYaw

        return RigidTransform(RollPitchYaw(np.radians(self.frame_rpy_deg)), np.array(self.frame_xyz, float))

    @property
    def X_GT(self) -> "RigidTransform":
        """The TCP in the grasp frame."""
        from pydrake.math import RigidTransform

        return RigidTransform([0.0, 0.0, self.grasp_depth])

    @property
    def X_HT(self) -> "RigidTransform":
        """The TCP in the hand frame."""
        from pydrake.math import RigidTransform

        return RigidTransform([0.0, 0.0, self.tcp_depth])

    @property
    def X_GH(self) -> "RigidTransform":
        """The hand frame in the grasp frame."""
        return self.X_GT @ self.X_HT.inverse()

    def joint_positions(self, position: float) -> dict[str, float]:
        """Each joint that moves with the driven one (the driven, the coupled and the mimic joints) at a
        driven-joint `position`."""
        return ({self.driven_joint: position} | {name: position for name in self.coupled_joints}
                | {name: multiplier * position + offset for name, multiplier, offset in self.mimics})

    def opening(self, position: float) -> float:
        """The jaws' opening [m] at a driven-joint position (linear from closed to open)."""
        return self.stroke * (position - self.closed_position) / (self.open_position - self.closed_position)

    @functools.cached_property
    def fingerprint(self) -> str:
        """12 hex digits of the hand's model file and every number and name here but its name and
        source (a field with a default leaves it out at the default, so a field added later keeps the
        hands of before as they were): data and models made with another hand carry another."""
        defaults = {f.name: f.default for f in dc.fields(self) if f.default is not dc.MISSING}
        fields = {k: v for k, v in dc.asdict(self).items()
                  if k not in ("name", "source", "model_url", "model_file", "cnn_weights", "hold_weights")
                  and not (k in defaults and v == defaults[k])}
        digest = hashlib.sha256(json.dumps(fields, sort_keys=True).encode())
        digest.update(Path(self.model_file or self.model_url).read_bytes())
        return digest.hexdigest()[:12]


def default_hand() -> HandSpec:
    """The shipped Franka hand, every arm's unless its file or `--hand` says otherwise."""
    return get_hand(DEFAULT_HAND)


def known_hands() -> list[str]:
    """The names of the shipped hands (`sdf/hands/NAME.yaml`)."""
    return sorted(p.stem for p in HANDS_DIR.glob("*.yaml"))


def get_hand(name: str = DEFAULT_HAND) -> HandSpec:
    """A shipped hand by name, or any hand by its YAML file; ValueError otherwise."""
    if name.endswith((".yaml", ".yml")):
        path = Path(name)
        if not path.is_file():
            raise ValueError(f"hand file not found: {path}")
        spec = _load_hand(path.resolve(), path.stat().st_mtime_ns)
        return dc.replace(spec, source=str(path.resolve()))
    path = HANDS_DIR / f"{name}.yaml"
    if not path.is_file():
        raise ValueError(f"unknown hand '{name}'; choose one of: {', '.join(known_hands())} "
                         "or a hand YAML file")
    return dc.replace(_load_hand(path, path.stat().st_mtime_ns), source=name)


# The hand record of a CNN with a hand channel (`learning.cnn.GraspCNN.hand_channel`): made for any
# parallel-jaw hand, told which by the hand's sizes
ANY_HAND = {"name": "any parallel-jaw hand", "fingerprint": "any"}


def hand_record(hand: HandSpec) -> dict:
    """What data manifests, model cards and reports record of the hand that made them."""
    return {"name": hand.name, "fingerprint": hand.fingerprint}


def check_hand_record(recorded: dict | None, hand: HandSpec, what: str) -> None:
    """ValueError, one line, when `what` (data, a model or a report whose `hand_record` is `recorded`)
    was made with another hand than `hand` (a model made for `ANY_HAND` goes with every hand)."""
    fingerprint = (recorded or {}).get("fingerprint")
    if fingerprint != hand.fingerprint and recorded != ANY_HAND:
        made = (f"the '{recorded.get('name')}' hand ({fingerprint})" if recorded
                else "no recorded hand")
        raise ValueError(f"{what}: made with {made}, not the '{hand.name}' hand ({hand.fingerprint}); "
                         "make them again with this hand")


def job_hand(recorded: dict, hand_file: str) -> HandSpec:
    """A collection job's hand in a worker: `hand_file` (a shipped hand's name or a hand YAML file; "":
    the Franka hand), refused when it is not the hand the job's manifest records."""
    hand = get_hand(hand_file or DEFAULT_HAND)
    check_hand_record(recorded, hand, "this job's folder")
    return hand


def check_model_hand(card: dict, hand: HandSpec, what: str) -> None:
    """ValueError when a model whose card is `card` was trained for another hand than `hand`."""
    check_hand_record(card.get("hand"), hand, what)


@functools.lru_cache(maxsize=8)
def _load_hand(path: Path, mtime_ns: int) -> HandSpec:
    from pydrake.common.yaml import yaml_load_typed

    try:
        config = yaml_load_typed(schema=HandConfig, filename=str(path))
    except (RuntimeError, ValueError) as e:
        raise ValueError(f"invalid hand file {path}: {str(e).splitlines()[0]}") from None
    try:
        spec = _spec_from_config(config, path)
        spec = dc.replace(spec, contact_filled=_check_model(spec))
    except ValueError as e:
        raise ValueError(f"hand file {path}: {e}") from None
    return spec


def _spec_from_config(config: HandConfig, path: Path) -> HandSpec:
    for field in ("name", "model", "base_link", "driven_joint"):
        if not getattr(config, field):
            raise ValueError(f"needs '{field}'")
    model = (path.parent / config.model).resolve()
    if not model.is_file():
        raise ValueError(f"model not found: {model}")
    if len(config.fingers) != 2:
        raise ValueError(f"'fingers' names the two finger links, got {len(config.fingers)}")
    for field in ("palm_size", "finger_size"):
        if len(getattr(config, field)) != 2:
            raise ValueError(f"'{field}' needs two sizes (along x_H, y_H)")
    for field in ("frame_xyz", "frame_rpy_deg"):
        if len(getattr(config, field)) != 3 or not np.isfinite(getattr(config, field)).all():
            raise ValueError(f"'{field}' needs three numbers")
    positive = ("grip_force", "stroke", "tcp_depth", "palm_depth", "finger_length")
    bad = [f for f in positive if not getattr(config, f) > 0]
    bad += [f for f in ("palm_size", "finger_size") if not all(v > 0 for v in getattr(config, f))]
    if bad:
        raise ValueError(f"{', '.join(bad)} must be positive numbers")
    commands = (config.open_position, config.closed_position, config.closed_on_nothing, config.grasp_depth)
    if not np.isfinite(commands).all():
        raise ValueError("open_position, closed_position and closed_on_nothing are needed")
    low, high = sorted((config.open_position, config.closed_position))
    if low == high or not low <= config.closed_on_nothing <= high:
        raise ValueError("closed_on_nothing must lie between closed_position and open_position, which differ")
    prepared = model
    if model.suffix.lower() == ".urdf":
        from drake_grasp.robot.model_files import PackageFinder, prepare_hand_model

        search = [(path.parent / folder).resolve() for folder in config.package_path]
        hint = f"set package_path (a folder holding the package) in {path}"
        prepared = prepare_hand_model(model, PackageFinder({}, search, model, hint), config.name)
    return HandSpec(
        name=config.name, model_url=str(prepared), model_file=str(model), base_link=config.base_link,
        fingers=tuple(config.fingers),
        driven_joint=config.driven_joint, coupled_joints=tuple(config.coupled_joints),
        open_position=float(config.open_position), closed_position=float(config.closed_position),
        closed_on_nothing=float(config.closed_on_nothing), grip_force=float(config.grip_force),
        stroke=float(config.stroke), tcp_depth=float(config.tcp_depth), palm_depth=float(config.palm_depth),
        palm_size=tuple(float(v) for v in config.palm_size), finger_length=float(config.finger_length),
        finger_size=tuple(float(v) for v in config.finger_size), grasp_depth=float(config.grasp_depth),
        mimics=mimic_joints(prepared, config.driven_joint),
        frame_xyz=tuple(float(v) for v in config.frame_xyz),
        frame_rpy_deg=tuple(float(v) for v in config.frame_rpy_deg),
        cnn_weights=str((path.parent / config.cnn_weights).resolve()) if config.cnn_weights else "",
        hold_weights=(config.hold_weights if config.hold_weights in ("", "none")
                      else str((path.parent / config.hold_weights).resolve())))


def mimic_joints(model: Path, driven: str) -> tuple[tuple[str, float, float], ...]:
    """The joints of a URDF or SDF model that mimic `driven` (its `<mimic>` tags): (joint, multiplier,
    offset) each. Drake couples them in the physics plant; the hand's kinematic models set them too."""
    from drake_grasp.robot.model_files import parse_model_xml

    root = parse_model_xml(model.read_text(errors="replace"), model, "hand")
    out = []
    for joint in root.iter("joint"):
        for mimic in joint.iter("mimic"):
            if mimic.get("joint") == driven:
                multiplier = float(mimic.get("multiplier", mimic.findtext("multiplier") or 1.0))
                offset = float(mimic.get("offset", mimic.findtext("offset") or 0.0))
                out.append((joint.get("name"), multiplier, offset))
    return tuple(out)


def _check_model(spec: HandSpec) -> int:
    """ValueError for a model that does not parse or lacks a named link or joint, or whose driven joint
    cannot reach the open and closed commands; else how many of its collision geometries name no
    hydroelastic contact (`HandSpec.contact_filled`)."""
    from pydrake.geometry import SceneGraph
    from pydrake.multibody.plant import MultibodyPlant

    from drake_grasp.robot.contact_model import bare_geometries
    from drake_grasp.robot.log import parser_warnings
    from drake_grasp.robot.paths import make_parser

    plant = MultibodyPlant(0.0)
    scene_graph = SceneGraph()
    plant.RegisterAsSourceForSceneGraph(scene_graph)
    renames = {spec.model_url: spec.model_file} if spec.model_file else {}
    try:
        with parser_warnings(f"hand '{spec.name}' ({spec.model_file or spec.model_url})", renames=renames):
            (instance,) = make_parser(plant).AddModels(spec.model_url)
    except (RuntimeError, ValueError) as e:
        message = str(e).splitlines()[0]
        for copy, original in renames.items():
            message = message.replace(copy, original)
        raise ValueError(f"could not parse the model: {message}") from None
    for link in (spec.base_link, *spec.fingers):
        if not plant.HasBodyNamed(link, instance):
            raise ValueError(f"the model has no link '{link}'")
    for joint in (spec.driven_joint, *spec.coupled_joints):
        if not plant.HasJointNamed(joint, instance):
            raise ValueError(f"the model has no joint '{joint}'")
    driven = plant.GetJointByName(spec.driven_joint, instance)
    if driven.num_positions() != 1:
        raise ValueError(f"the driven joint '{spec.driven_joint}' must have one degree of freedom")
    lower, upper = driven.position_lower_limits()[0], driven.position_upper_limits()[0]
    for field in ("open_position", "closed_position"):
        if not lower <= getattr(spec, field) <= upper:
            raise ValueError(f"{field} {getattr(spec, field)} is outside the driven joint's limits "
                             f"[{lower:g}, {upper:g}]")
    bodies = [plant.get_body(i) for i in plant.GetBodyIndices(instance)]
    return len(bare_geometries(plant, scene_graph.model_inspector(), bodies))
