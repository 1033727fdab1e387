"""Any URDF or SDF arm, described by a YAML file: `--robot path/to/arm.yaml` wherever `--robot` goes.

    name: iiwa
    model: kuka_iiwa/model.urdf      # URDF or SDF, relative to this file
    package_xml: ""                  # optional: its package.xml, for package:// mesh paths
    package_path: []                 # optional: folders that hold the packages package:// names
    base_link: lbr_iiwa_link_0       # welded at the world origin: the base frame B (default: the
                                     # link the model welds to a `world` link, as ROS URDFs do)
    flange: lbr_iiwa_link_7          # the body or frame the hand mounts to
    mount_xyz: [0.0, 0.0, 0.0]       # the hand's frame in the flange frame [m]
    mount_rpy_deg: [0.0, 0.0, 0.0]
    q_home: [0.0, 0.6, 0.0, -1.6, 0.0, 0.9, 0.0]   # one per joint, base to flange [rad or m]
    # optional, one number per joint, else the model's: q_lower, q_upper, v_max, effort_max
    filter_within: 1                 # ignore contact between links at most this many joints apart
    reachability_weights: ""         # this arm's RP (default: reachability_<name>.pt beside this file)
    hand: ""                         # the hand on the flange: a shipped hand's name or a hand YAML file
                                     # relative to this file (default: the Franka hand)

The model is made ready for Drake, as ROS and Gazebo tools write them: STL and DAE
meshes (which Drake cannot collide) become OBJ files whose convex hulls Drake uses;
`package://` and `model://` paths resolve through `package_xml`, then `package_path`,
then the folders above the model file (a package is a folder of its name); a `world`
link and the joint that welds the base to it go (the base is welded at the world
origin); ROS transmissions go (each arm joint gets one actuator, with its URDF effort
limit); movable joints off the base-to-flange chain (a gripper's, mimic joints) are
fixed; links within `filter_within` joints of each other get a collision filter group
(real arms overlap at their joints). The result is written once to a cache folder
(`DRAKE_GRASP_CACHE`, default `~/.cache/drake_grasp`), line for line with the user's
file, so that Drake's messages name the user's file and its lines. The arm's joints are
the 1-DoF joints from the base to the flange; a continuous one without q_lower/q_upper
gets [-2 pi, 2 pi]. A model that does not parse, a link or frame that does not exist, a
mimic joint on the chain, a home configuration of the wrong length, outside the limits
or in collision: one-line ValueErrors.
"""

# No `from __future__ import annotations`: yaml_load_typed reads the dataclass field types.
import dataclasses as dc
import functools
import json
import logging
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from pydrake.common.yaml import yaml_load_typed
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant

from drake_grasp.robot.hand import get_hand
from drake_grasp.robot.log import parser_warnings
from drake_grasp.robot.model_files import (
    PackageFinder,
    Preparation,
    placeholder,
    prepared_copy,
    remove_transmissions,
)
from drake_grasp.robot.paths import cache_dir
from drake_grasp.robot.specs import ROBOTS, RobotSpec

_log = logging.getLogger(__name__)

DEFAULT_V_MAX = 2.0  # rad/s (or m/s), for a joint whose model gives no finite velocity limit
DEFAULT_EFFORT = 100.0  # N m (or N), for a joint without an actuator effort limit
CONTINUOUS_LIMIT = 2 * np.pi  # [rad] the range given to a continuous arm joint
WORLD = "world"


@dc.dataclass
class ArmConfig:
    name: str = ""
    model: str = ""
    package_xml: str = ""
    package_path: list[str] = dc.field(default_factory=list)
    base_link: str = ""
    flange: str = ""
    mount_xyz: list[float] = dc.field(default_factory=lambda: [0.0, 0.0, 0.0])
    mount_rpy_deg: list[float] = dc.field(default_factory=lambda: [0.0, 0.0, 0.0])
    q_home: list[float] = dc.field(default_factory=list)
    q_lower: list[float] = dc.field(default_factory=list)
    q_upper: list[float] = dc.field(default_factory=list)
    v_max: list[float] = dc.field(default_factory=list)
    effort_max: list[float] = dc.field(default_factory=list)
    filter_within: int = 1
    reachability_weights: str = ""
    hand: str = ""


def get_robot(name: str, hand: str = "") -> RobotSpec:
    """The spec of a built-in arm by name, or of any arm by its YAML description, with its own hand or
    `hand` (a shipped hand's name or a hand YAML file; "": the arm's); ValueError otherwise."""
    if name.endswith((".yaml", ".yml")):
        robot = load_arm(name)
    else:
        try:
            robot = ROBOTS[name]
        except KeyError:
            raise ValueError(
                f"unknown robot '{name}'; choose one of: {', '.join(sorted(ROBOTS))} or an arm YAML file"
            ) from None
    return robot.with_hand(get_hand(hand)) if hand else robot


def load_arm(path: str | Path) -> RobotSpec:
    """The RobotSpec of the arm a YAML file describes (its model prepared and checked), made once per
    process for each version of the file."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"arm file not found: {path}")
    return _load_arm(path.resolve(), path.stat().st_mtime_ns, str(cache_dir()))


@functools.lru_cache(maxsize=8)
def _load_arm(path: Path, mtime_ns: int, cache: str) -> RobotSpec:
    try:
        config = yaml_load_typed(schema=ArmConfig, filename=str(path))
    except (RuntimeError, ValueError) as e:
        raise ValueError(f"invalid arm file {path}: {str(e).splitlines()[0]}") from None
    for field in ("name", "model", "flange"):
        if not getattr(config, field):
            raise ValueError(f"arm file {path} needs '{field}'")
    model = (path.parent / config.model).resolve()
    if not model.is_file():
        raise ValueError(f"arm model not found: {model}")
    packages = {}
    if config.package_xml:
        package_xml = (path.parent / config.package_xml).resolve()
        try:
            packages[ET.parse(package_xml).getroot().findtext("name")] = package_xml.parent
        except (OSError, ET.ParseError) as e:
            raise ValueError(f"cannot read the arm's package_xml {package_xml}: {e}") from None
    search = [(path.parent / folder).resolve() for folder in config.package_path]
    hint = f"set package_path (a folder holding the package) or package_xml in {path}"
    prepared = prepare_model(model, PackageFinder(packages, search, model, hint), config)
    config = dc.replace(config, base_link=_base_link(config, prepared, path))
    spec = _spec_from_model(config, prepared, source=str(path.resolve()), user_model=model)
    weights = config.reachability_weights or f"reachability_{config.name}.pt"
    spec = dc.replace(spec, reachability_weights=str((path.parent / weights).resolve()))
    if config.hand:
        hand = config.hand
        spec = spec.with_hand(get_hand(str((path.parent / hand).resolve()) if hand.endswith((".yaml", ".yml"))
                                       else hand))
    _check_home(spec)
    return spec


# -- the model, made ready for Drake --------------------------------------------------------
def prepare_model(model: Path, packages: PackageFinder, config: ArmConfig) -> Path:
    """A copy of the arm's model, line for line, with absolute OBJ meshes, no world link or transmissions,
    the off-chain joints fixed and link collision filters, at a stable cache path (`Preparation`'s
    JSON beside it)."""

    def edit(root: ET.Element, urdf: bool, preparation: Preparation) -> None:
        if urdf:
            _remove_world_link(root, preparation)
            remove_transmissions(root)
            base = config.base_link if config.base_link not in ("", WORLD) else preparation.world_child
            _fix_off_chain_joints(root, base, config.flange, preparation)
            _add_link_filters(root, config.filter_within)
            _give_massless_links_mass(root)
        else:
            _remove_world_joints_sdf(root, preparation)

    return prepared_copy(model, packages, kind="arm", name=config.name, edit=edit,
                         key=f"{config.filter_within} {config.base_link} {config.flange}")


def preparation_of(prepared: Path) -> Preparation:
    return Preparation(**json.loads(prepared.with_suffix(".prepared.json").read_text()))


def _remove_world_link(robot: ET.Element, preparation: Preparation) -> None:
    """The `world` link and the fixed joint that welds the base to it go: the base is welded at the origin."""
    for joint in robot.findall("joint"):
        parent = joint.find("parent")
        if parent is None or parent.get("link") != WORLD:
            continue
        child = joint.find("child").get("link")
        if joint.get("type") != "fixed":
            raise ValueError(f"joint '{joint.get('name')}' connects '{WORLD}' to '{child}' as a "
                             f"{joint.get('type')} joint; an arm's base must be welded (fixed) to the world")
        origin = joint.find("origin")
        offset = [] if origin is None else [origin.get("xyz", "0 0 0"), origin.get("rpy", "0 0 0")]
        if any(float(v) != 0.0 for part in offset for v in part.split()):
            preparation.notes.append(f"joint '{joint.get('name')}' places '{child}' at xyz {offset[0]} rpy "
                                     f"{offset[1]}; the base is welded at the world origin instead")
        preparation.world_child = child
        placeholder(robot, joint, f"{joint.get('name')} (welds the base to the world)")
    for link in robot.findall("link"):
        if link.get("name") == WORLD:
            placeholder(robot, link, "world link")


def _remove_world_joints_sdf(root: ET.Element, preparation: Preparation) -> None:
    """An SDF model's joint from `world` to its base goes (the base is welded at the origin)."""
    for model in root.iter("model"):
        for joint in model.findall("joint"):
            if (joint.findtext("parent") or "").strip() == WORLD:
                if joint.get("type") != "fixed":
                    raise ValueError(f"joint '{joint.get('name')}' connects '{WORLD}' to the arm as a "
                                     f"{joint.get('type')} joint; an arm's base must be fixed to the world")
                preparation.world_child = (joint.findtext("child") or "").strip()
                placeholder(model, joint, f"{joint.get('name')} (welds the base to the world)")


def _fix_off_chain_joints(robot: ET.Element, base: str, flange: str, preparation: Preparation) -> None:
    """Movable joints off the base-to-flange chain become fixed (a gripper's, a mimic joint's); a mimic
    joint on the chain is a ValueError."""
    joints = robot.findall("joint")
    inboard = {j.find("child").get("link"): j for j in joints if j.find("child") is not None}
    chain, link = set(), flange
    while link in inboard and link != base:
        chain.add(inboard[link].get("name"))
        link = inboard[link].find("parent").get("link")
    if link != base:  # (the flange is a frame, or not below the base: _chain says which)
        return
    fixed = []
    for joint in joints:
        name, mimic = joint.get("name"), joint.find("mimic")
        if name in chain:
            if mimic is not None:
                raise ValueError(f"joint '{name}' between the base and the flange mimics another joint; an "
                                 "arm's joints must be independent")
            continue
        if joint.get("type") not in ("fixed", "floating", "planar"):
            joint.set("type", "fixed")
            if mimic is not None:
                joint.remove(mimic)
            fixed.append(name)
    if fixed:
        preparation.notes.append(f"joints off the base-to-flange chain are fixed at zero: {', '.join(fixed)}")


def _base_link(config: ArmConfig, prepared: Path, arm_file: Path) -> str:
    """The arm's base link: the YAML's, or the link the model welded to `world` (also for `world`)."""
    preparation = preparation_of(prepared)
    _note(config.name, preparation.notes)
    if config.base_link and config.base_link != WORLD:
        return config.base_link
    if not preparation.world_child:
        raise ValueError(f"arm file {arm_file} needs 'base_link' (its model welds no link to '{WORLD}')")
    return preparation.world_child


def _note(arm: str, notes: list[str]) -> None:
    """Prints the arm's notes once, in the main process (workers load the arm again)."""
    import multiprocessing

    if multiprocessing.parent_process() is None:
        for note in notes:
            _log.warning(f"arm '{arm}': {note}")


def _give_massless_links_mass(robot: ET.Element) -> None:
    """A link of zero mass (some models give the fixed base none) gets a gram: Drake needs mass > 0."""
    for mass in robot.iter("mass"):  # (only <inertial> elements hold a <mass>)
        if float(mass.get("value", "1")) <= 0.0:
            mass.set("value", "0.001")


def _add_link_filters(robot: ET.Element, within: int) -> None:
    """A Drake collision filter group for each link and its neighbours up to `within` joints away."""
    # Top-level elements only: a ROS <transmission> also holds <joint> elements (without a child).
    parent_of = {j.find("child").get("link"): j.find("parent").get("link") for j in robot.findall("joint")}
    drake = "{http://drake.mit.edu}"
    for link in (e.get("name") for e in robot.findall("link")):
        group = ET.SubElement(robot, f"{drake}collision_filter_group", name=f"near_{link}")
        ET.SubElement(group, f"{drake}member", link=link)
        ancestor = link
        for _ in range(within):
            ancestor = parent_of.get(ancestor)
            if ancestor is None:
                break
            ET.SubElement(group, f"{drake}member", link=ancestor)
        ET.SubElement(group, f"{drake}ignored_collision_filter_group", name=f"near_{link}")


# -- the spec ---------------------------------------------------------------------------------
def _spec_from_model(config: ArmConfig, model: Path, *, source: str, user_model: Path) -> RobotSpec:
    plant = MultibodyPlant(0.0)
    renames = {str(model): str(user_model)}
    try:
        with parser_warnings(f"arm '{config.name}' ({user_model})", renames=renames):
            (instance,) = Parser(plant).AddModels(str(model))
    except (RuntimeError, ValueError) as e:
        message = str(e).splitlines()[0].replace(str(model), str(user_model))
        raise ValueError(f"could not parse the arm model {user_model}: {message}") from None
    if not plant.HasBodyNamed(config.base_link, instance):
        raise ValueError(f"the arm model has no link '{config.base_link}' (base_link)")
    if not plant.HasFrameNamed(config.flange, instance):
        raise ValueError(f"the arm model has no frame '{config.flange}' (flange)")
    plant.WeldFrames(plant.world_frame(), plant.GetBodyByName(config.base_link, instance).body_frame())
    plant.Finalize()
    joints = _chain(plant, instance, config.base_link, config.flange)
    n = len(joints)

    def per_joint(values: list[float], field: str, default: list[float]) -> tuple[float, ...]:
        if values and len(values) != n:
            raise ValueError(f"{field} has {len(values)} values but the arm has {n} joints")
        return tuple(float(v) for v in (values or default))

    lower = [j.position_lower_limits()[0] for j in joints]
    upper = [j.position_upper_limits()[0] for j in joints]
    continuous = [j.name() for j, lo, up in zip(joints, lower, upper, strict=True)
                  if not (np.isfinite(lo) or np.isfinite(up))]
    if continuous and not (config.q_lower or config.q_upper):
        _note(config.name, [f"continuous joint(s) {', '.join(continuous)} limited to [-2 pi, 2 pi] "
                            "(set q_lower and q_upper to change)"])
        lower = [v if np.isfinite(v) else -CONTINUOUS_LIMIT for v in lower]
        upper = [v if np.isfinite(v) else CONTINUOUS_LIMIT for v in upper]
    q_lower = per_joint(config.q_lower, "q_lower", lower)
    q_upper = per_joint(config.q_upper, "q_upper", upper)
    if not (np.isfinite(q_lower).all() and np.isfinite(q_upper).all()):
        raise ValueError("every arm joint needs finite position limits (set q_lower and q_upper)")
    v_model = [v if np.isfinite(v := j.velocity_upper_limits()[0]) else DEFAULT_V_MAX for j in joints]
    urdf_efforts = _urdf_efforts(model)
    effort_model = [urdf_efforts.get(j.name()) or _effort(plant, j) for j in joints]
    q_home = per_joint(config.q_home, "q_home", [])
    if len(q_home) != n:
        raise ValueError(f"q_home needs {n} values (the arm has {n} joints), got {len(q_home)}")
    outside = [i + 1 for i in range(n) if not q_lower[i] <= q_home[i] <= q_upper[i]]
    if outside:
        raise ValueError(f"q_home is outside the joint limits at joint(s) {outside}")
    shoulder, reach = _reach_bound(plant, joints, config.flange, instance)
    return RobotSpec(
        name=config.name, model_url=model.as_uri(), base_link=config.base_link, flange_link=config.flange,
        joint_names=tuple(j.name() for j in joints), q_home=q_home, q_lower=q_lower, q_upper=q_upper,
        v_max=per_joint(config.v_max, "v_max", v_model),
        effort_max=per_joint(config.effort_max, "effort_max", effort_model),
        source=source, mount_xyz=tuple(config.mount_xyz), mount_rpy_deg=tuple(config.mount_rpy_deg),
        shoulder=tuple(float(x) for x in shoulder), reach=float(reach), model_file=str(user_model))


def _urdf_efforts(model: Path) -> dict[str, float]:
    """Each URDF joint's positive `<limit effort>` (an SDF model gives its actuators' own)."""
    if model.suffix.lower() != ".urdf":
        return {}
    efforts = {}
    for joint in ET.parse(model).getroot().findall("joint"):
        limit = joint.find("limit")
        if limit is not None and float(limit.get("effort", "0") or 0) > 0:
            efforts[joint.get("name")] = float(limit.get("effort"))
    return efforts


def _chain(plant: MultibodyPlant, instance, base_link: str, flange: str) -> list:
    """The 1-DoF joints from the base link to the flange's body, base first."""
    joints = [plant.get_joint(i) for i in plant.GetJointIndices(instance)]
    inboard = {joint.child_body().index(): joint for joint in joints}
    body = plant.GetFrameByName(flange, instance).body()
    base = plant.GetBodyByName(base_link, instance).index()
    joints = []
    while body.index() != base:
        joint = inboard.get(body.index())
        if joint is None:
            raise ValueError(f"the flange '{flange}' is not connected to the base link '{base_link}'")
        if joint.num_positions() == 1:
            joints.append(joint)
        elif joint.num_positions() != 0:
            raise ValueError(f"joint '{joint.name()}' has {joint.num_positions()} degrees of freedom; "
                             "an arm's joints must have one")
        body = joint.parent_body()
    if not joints:
        raise ValueError("the arm has no joint between its base link and its flange")
    return joints[::-1]


def _effort(plant: MultibodyPlant, joint) -> float:
    for i in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(i)
        if actuator.joint().index() == joint.index() and np.isfinite(actuator.effort_limit()):
            return float(actuator.effort_limit())
    return DEFAULT_EFFORT


def _reach_bound(plant: MultibodyPlant, joints: list, flange: str, instance) -> tuple[np.ndarray, float]:
    """Joint 1's centre and an upper bound on the flange's distance from it: the sum of the (rigid)
    distances between consecutive joint centres and from the last to the flange."""
    context = plant.CreateDefaultContext()
    centres = [j.frame_on_child().CalcPoseInWorld(context).translation() for j in joints]
    centres.append(plant.GetFrameByName(flange, instance).CalcPoseInWorld(context).translation())
    reach = sum(float(np.linalg.norm(b - a)) for a, b in zip(centres[:-1], centres[1:], strict=True))
    return np.array(centres[0], dtype=float), reach + 0.01


def _check_home(spec: RobotSpec) -> None:
    from drake_grasp.robot.collision import CollisionModel

    world = CollisionModel(spec, table_height=0.0)
    if not world.is_free(np.array(spec.q_home)):
        raise ValueError("the home configuration q_home is in collision (with the arm itself, the hand or "
                         "the table at z = 0)")
