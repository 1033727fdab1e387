"""One contact model for every object and hand: the project's hydroelastic properties, filled in
wherever a file gives none.

The trials, the closed loop and the shipped models assume compliant hydroelastic
objects against rigid hydroelastic fingers and table. Object files written for other
simulators (Gazebo's SDF, ROS URDF, a bare mesh) carry mass and shapes but no Drake
contact tags: parsed as they are, they stay rigid and fall back to point contact
with the rigid fingers (round bodies slip out, violent contacts can diverge). So
every object collision geometry without a hydroelastic compliance type gets
`ObjectContact`'s; a geometry that names one keeps all of its own properties. A
friction the file does not give (Drake's parsers then report mu = 1.0) becomes the
project's; a friction the file gives (SDF `<surface><friction>`, `drake:mu_*`) is kept.
A mesh shape that is not convex collides as its convex hull (Drake's rule for compliant
meshes); give concave objects as bare OBJ files, which are decomposed into convex pieces.

A hand's file is filled the same way with rigid hydroelastic geometry (`fill_hand_contact`): a
gripper published for ROS or another simulator (a URDF with no Drake tags) would otherwise meet
the compliant objects in point contact at Drake's default stiffness, and its pads sink through
them under the grip (the jaws close "on nothing" around an object they hold). Its friction stays
the file's, or Drake's 1.0 where the file gives none.
"""

from __future__ import annotations

import dataclasses as dc
from collections.abc import Callable, Sequence

from pydrake.geometry import (
    AddCompliantHydroelasticProperties,
    AddRigidHydroelasticProperties,
    GeometryId,
    ProximityProperties,
    RoleAssign,
    SceneGraph,
    SceneGraphInspector,
)
from pydrake.multibody.plant import CoulombFriction, MultibodyPlant
from pydrake.multibody.tree import RigidBody

UNSPECIFIED_FRICTION = 1.0  # what Drake's SDF and URDF parsers report for a geometry that names none


@dc.dataclass(frozen=True)
class ObjectContact:
    """The contact properties of the project's objects (the shipped sets and generated corpora)."""

    hydroelastic_modulus: float = 1e6  # [Pa] compliant against the rigid fingers and table
    resolution_hint: float = 0.01  # [m] tessellation of round shapes for the hydroelastic mesh
    friction: float = 0.8  # static and dynamic Coulomb friction

    def sdf_tags(self, friction: float | None = None) -> str:
        """These properties as an SDF `<drake:proximity_properties>` element (`friction` overrides)."""
        return self._tags(friction, lambda name, value: f"<drake:{name}>{value}</drake:{name}>")

    def urdf_tags(self, friction: float | None = None) -> str:
        """`sdf_tags` in URDF's form (values as `value` attributes)."""
        return self._tags(friction, lambda name, value: f'<drake:{name} value="{value}"/>')

    def _tags(self, friction: float | None, tag: Callable[[str, str], str]) -> str:
        mu = f"{self.friction if friction is None else friction:.3f}"
        return ("<drake:proximity_properties><drake:compliant_hydroelastic/>"
                + tag("hydroelastic_modulus", f"{self.hydroelastic_modulus:g}")
                + tag("mesh_resolution_hint", f"{self.resolution_hint:g}")
                + tag("mu_dynamic", mu) + tag("mu_static", mu) + "</drake:proximity_properties>")

OBJECT_CONTACT = ObjectContact()


def has_compliance(properties: ProximityProperties | None) -> bool:
    """Whether a geometry's proximity properties name a hydroelastic compliance type."""
    return properties is not None and properties.HasProperty("hydroelastic", "compliance_type")


def filled_properties(properties: ProximityProperties | None,
                      contact: ObjectContact = OBJECT_CONTACT) -> ProximityProperties:
    """`properties` with the project's compliant hydroelastic model, and its friction where none is given."""
    filled = ProximityProperties() if properties is None else ProximityProperties(properties)
    AddCompliantHydroelasticProperties(contact.resolution_hint, contact.hydroelastic_modulus, filled)
    given = filled.GetPropertyOrDefault("material", "coulomb_friction", None)
    if given is None or (given.static_friction() == UNSPECIFIED_FRICTION
                         and given.dynamic_friction() == UNSPECIFIED_FRICTION):
        friction = CoulombFriction(contact.friction, contact.friction)
        if given is None:
            filled.AddProperty("material", "coulomb_friction", friction)
        else:
            filled.UpdateProperty("material", "coulomb_friction", friction)
    return filled


def bare_geometries(plant: MultibodyPlant, inspector: SceneGraphInspector,
                    bodies: Sequence[RigidBody]) -> list[GeometryId]:
    """The collision geometries of `bodies` that name no hydroelastic compliance."""
    return [g for body in bodies for g in plant.GetCollisionGeometriesForBody(body)
            if not has_compliance(inspector.GetProximityProperties(g))]


def fill_contact_model(plant: MultibodyPlant, scene_graph: SceneGraph, bodies: Sequence[RigidBody],
                       contact: ObjectContact = OBJECT_CONTACT) -> list[RigidBody]:
    """Gives every collision geometry of `bodies` that lacks a compliance type the project's contact
    model (before `plant.Finalize()`); returns the bodies that got it."""
    inspector = scene_graph.model_inspector()
    filled = []
    for body in bodies:
        geometries = bare_geometries(plant, inspector, [body])
        for g in geometries:
            scene_graph.AssignRole(plant.get_source_id(), g,
                                   filled_properties(inspector.GetProximityProperties(g), contact),
                                   RoleAssign.kReplace)
        if geometries:
            filled.append(body)
    return filled


def fill_hand_contact(plant: MultibodyPlant, scene_graph: SceneGraph, bodies: Sequence[RigidBody]) -> int:
    """Makes every collision geometry of a hand's `bodies` that lacks a compliance type rigid
    hydroelastic, keeping its other properties (before `plant.Finalize()`); returns how many."""
    inspector = scene_graph.model_inspector()
    geometries = bare_geometries(plant, inspector, bodies)
    for g in geometries:
        given = inspector.GetProximityProperties(g)
        filled = ProximityProperties() if given is None else ProximityProperties(given)
        AddRigidHydroelasticProperties(filled)
        if not filled.HasProperty("material", "coulomb_friction"):
            filled.AddProperty("material", "coulomb_friction",
                               CoulombFriction(UNSPECIFIED_FRICTION, UNSPECIFIED_FRICTION))
        scene_graph.AssignRole(plant.get_source_id(), g, filled, RoleAssign.kReplace)
    return len(geometries)
