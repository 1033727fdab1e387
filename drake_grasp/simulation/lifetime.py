"""Freeing a finished diagram that holds systems written in Python.

pydrake (1.51) never frees a system implemented in Python once a diagram has owned it: the C++ side
keeps a reference to its Python object that the garbage collector cannot see. Such a system's
attributes (the plant it reads, a planner, a policy's models) and pydrake's reference-cycle
bookkeeping in its `__dict__` then keep the whole diagram alive, with its plant, scene graph, render
engine and contexts: 0.1-0.2 GB a closed-loop episode, which a worker running a hundred episodes
cannot afford. `release_python_systems` empties those systems once their diagram is done with, so the
diagram and everything it owns are freed; only the emptied Python shells stay.
"""

from __future__ import annotations

from collections.abc import Iterator

from pydrake.systems.framework import Diagram, System


def python_systems(diagram: Diagram) -> Iterator[System]:
    """The systems in `diagram`, nested diagrams' included, whose classes are written in Python
    (subclasses of pydrake's `LeafSystem` or `Diagram`), the diagram itself included if it is one."""
    if _written_in_python(diagram):
        yield diagram
    for system in diagram.GetSystems():
        if isinstance(system, Diagram):
            yield from python_systems(system)
        elif _written_in_python(system):
            yield system


def release_python_systems(diagram: Diagram) -> None:
    """Drops every attribute of `diagram`'s Python systems (`python_systems`) so that the diagram can be
    freed. The diagram must not be simulated or evaluated afterwards."""
    for system in list(python_systems(diagram)):  # (all found before any is emptied)
        system.__dict__.clear()


def _written_in_python(system: System) -> bool:
    return not type(system).__module__.startswith("pydrake.")
