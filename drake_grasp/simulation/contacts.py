"""Which bodies touch: the plant's contact results as pairs of body indices.

The closed loop judges a grasp by what the fingers touch and counts the arm's
contacts with objects during transit; both only need "body A touches body B",
whether the contact is hydroelastic (reported per geometry) or point contact.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from pydrake.common.value import AbstractValue, Value
from pydrake.multibody.plant import ContactResults, MultibodyPlant
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.framework import LeafSystem

BodyPairs = frozenset  # of (smaller, larger) body index pairs, as ints


def geometry_bodies(plant: MultibodyPlant) -> dict:
    """Collision geometry id -> body index, for every body of a finalized plant."""
    return {g: i for i in range(plant.num_bodies())
            for g in plant.GetCollisionGeometriesForBody(plant.get_body(BodyIndex(i)))}


def touching_pairs(results: ContactResults, bodies_of_geometry: dict) -> BodyPairs:
    """The pairs of bodies in contact, each as (smaller index, larger index)."""
    pairs = set()
    for i in range(results.num_point_pair_contacts()):
        info = results.point_pair_contact_info(i)
        pairs.add((int(info.bodyA_index()), int(info.bodyB_index())))
    for i in range(results.num_hydroelastic_contacts()):
        surface = results.hydroelastic_contact_info(i).contact_surface()
        pairs.add((bodies_of_geometry[surface.id_M()], bodies_of_geometry[surface.id_N()]))
    return frozenset((min(a, b), max(a, b)) for a, b in pairs)


class BodyContacts(LeafSystem):
    """contact_results in, `body_contacts` (a frozenset of body index pairs) out."""

    def __init__(self, plant: MultibodyPlant):
        super().__init__()
        self._bodies_of_geometry = geometry_bodies(plant)
        self._results = self.DeclareAbstractInputPort("contact_results", AbstractValue.Make(ContactResults()))
        self.DeclareAbstractOutputPort("body_contacts", lambda: Value(frozenset()), self._calc)

    def _calc(self, context, output) -> None:
        output.set_value(touching_pairs(self._results.Eval(context), self._bodies_of_geometry))


def touching(pairs: BodyPairs, body: int, others: Iterable[int]) -> set[int]:
    """Which of `others` touch `body`."""
    return {o for o in others if (min(body, o), max(body, o)) in pairs}


def between_fingers(pairs: BodyPairs, body: int, fingers: Sequence[int]) -> bool:
    """Whether `body` touches every finger (it is in the hand)."""
    return len(touching(pairs, body, fingers)) == len(fingers)
