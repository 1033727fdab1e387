"""What the cell's perception makes of its cameras' clouds, besides the objects (a scenario's field)."""

# No `from __future__ import annotations`: yaml_load_typed reads the dataclass field types.
import dataclasses as dc


@dc.dataclass
class PerceptionConfig:
    """Scene structure and free space (`perception.cloud`); the defaults see objects on a bare table."""

    # Segments (`cloud.segment_objects`) whose footprint is longer than this are scene structure
    # (furniture, a shelf): no grasp candidates on them, but part of the CNN's input and of the planning
    # world [m]; 0: every point above the table belongs to an object.
    structure_extent: float = 0.0
    # The cloud carries its cameras' rays, so that planning counts the space a camera saw through as free
    # (a camera from the side sees under a shelf); False: under an observed surface is occupied.
    free_space: bool = False
    # Isolated points above the table (`cloud.remove_specks`: a real sensor's noise) are dropped. Off in the
    # simulated cell, whose clouds have few (its objects' sparse edge points are most of what it drops);
    # `detect`, which reads real frames, turns it on.
    remove_specks: bool = False

    def __post_init__(self) -> None:
        if self.structure_extent < 0.0:
            raise ValueError(f"structure_extent must be >= 0, got {self.structure_extent}")
