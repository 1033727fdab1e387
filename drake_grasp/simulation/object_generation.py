"""Procedural graspable objects: a corpus of shapes for training the stability CNN beyond eight blocks.

Object k of a corpus is a pure function of (seed, k, the families allowed). Families:
- primitives: box, cylinder, sphere, capsule;
- compositions of primitives: L and T shapes, mugs (a wall of staves, a bottom, a handle),
  bottles (body, shoulder, neck), tools (a handle and a head); on request only (`EXTRA_FAMILIES`),
  stepped bottles (body and neck without a shoulder, some capped);
- meshes: superquadrics (pinched and boxy), extrusions of random star polygons, solids
  of revolution of random profiles (vases, spools), hulls of random points;
- household objects at their real sizes (`HOUSEHOLD_FAMILIES`, on request: `--families household`):
  packs and cartons (tea packs to cereal boxes), cans and jars, bottles, bowls and plates, mugs,
  hammers and screwdrivers, balls, toy cars, shoes and fruit. Many are as wide as the hand opens
  or wider in some direction, so that trials teach where the hand fits (the thin side of a box,
  a rim, a handle) and where it does not; they stand in their natural upright pose in their own
  frame (+z up), which a packed scene keeps.
Sizes of the other families lie between about 1 and 15 cm (`MAX_EXTENT`) and every object has a
graspable width under the hand's 8 cm stroke however it comes to rest: a solid (one body, not a
composition) is redrawn until the middle of its three extents is under the stroke, since a slab lying
on its broad face offers the hand only its two larger extents (compositions have graspable
parts by construction); masses are 20-500 g (a density of 150-1200 kg/m^3, clipped);
friction 0.4-1.0. An elongated corpus (`elongation`, for example (1.3, 2.0)) stretches every
object along its longest extent by a factor drawn from that range: bottles, tools and bars of
up to about 30 cm, heavier, whose grasps far from the centre of mass pivot in the hand. The
draw comes from a stream of its own, so the plain corpus of a seed is unchanged. A concave mesh is
decomposed into convex pieces with CoACD, so that Drake's contact sees its real shape (a convex
mesh is one piece); compositions are convex parts already. Each piece is compliant hydroelastic,
as the shipped objects.
"""

from __future__ import annotations

import dataclasses as dc
import math
from pathlib import Path

import numpy as np
import trimesh

from drake_grasp.robot.contact_model import OBJECT_CONTACT
from drake_grasp.robot.object_files import hull_mesh, outward

FAMILIES = ("box", "cylinder", "sphere", "capsule", "l_shape", "t_shape", "mug", "bottle", "tool",
            "superquadric", "extrusion", "revolution", "hull")
# Families only on request (`--families`); the default corpora draw from FAMILIES alone.
EXTRA_FAMILIES = ("stepped_bottle",)
MAX_GRASP_WIDTH = 0.075  # [m], under the 8 cm stroke
MAX_EXTENT = 0.155  # [m] no object is longer than this (unless elongated)
GENERATOR_VERSION = 2  # 2: solids redrawn until graspable lying flat (`rests_graspable`)
MAX_ELONGATION = 2.5  # an elongated object is at most this many times its drawn length
MAX_REDRAWS = 100  # draws of a solid's shape before generate_object gives up
MASS_RANGE = (0.02, 0.5)  # [kg]
DENSITY_RANGE = (150.0, 1200.0)  # [kg/m^3]
HOUSEHOLD_MASS_RANGE = (0.03, 1.5)  # [kg]: a tea pack to a full cereal box or bottle
FRICTION_RANGE = (0.4, 1.0)
CONVEX_VOLUME_RATIO = 0.97  # a mesh filling less of its hull than this is decomposed
COACD_THRESHOLD = 0.06  # CoACD's concavity tolerance
COACD_MAX_PIECES = 12
MESH_FOLDER = "meshes"
MIN_PIECE_VOLUME = 1e-8  # [m^3], 10 mm^3
MIN_PIECE_THICKNESS = 0.001  # [m]
# Contact cost grows with the pieces' detail: Drake's compliant mesh of a convex piece has a
# tetrahedron per hull face, a sphere or capsule is refined to the resolution hint.
MAX_HULL_VERTICES = 48  # a convex piece with more is the hull of 48 of them (farthest-point sampled)
MESH_RESOLUTION_HINT = 0.02  # [m] spheres, capsules and cylinders: within about 2 mm of the true surface


@dc.dataclass
class Piece:
    """One convex part of an object, in the object's frame: a primitive or a convex mesh."""

    kind: str  # "box", "cylinder", "sphere", "capsule" or "mesh"
    size: tuple[float, ...] = ()  # box (x, y, z); cylinder and capsule (radius, length); sphere (radius,)
    X: np.ndarray = dc.field(default_factory=lambda: np.eye(4))  # pose in the object frame
    mesh: trimesh.Trimesh | None = None

    def trimesh(self) -> trimesh.Trimesh:
        """The piece as a closed triangle mesh in the object frame (for mass properties)."""
        make = {"box": lambda: trimesh.creation.box(extents=self.size),
                "cylinder": lambda: trimesh.creation.cylinder(radius=self.size[0], height=self.size[1]),
                "sphere": lambda: trimesh.creation.icosphere(subdivisions=2, radius=self.size[0]),
                "capsule": lambda: trimesh.creation.capsule(height=self.size[1], radius=self.size[0]),
                "mesh": lambda: self.mesh.copy()}[self.kind]
        mesh = make()
        if self.kind != "mesh":
            mesh.apply_transform(self.X)
        return mesh


@dc.dataclass
class GeneratedObject:
    name: str
    family: str
    pieces: list[Piece]
    mass: float
    friction: float
    rgba: tuple[float, float, float, float]
    com: np.ndarray = dc.field(default_factory=lambda: np.zeros(3))
    inertia: np.ndarray = dc.field(default_factory=lambda: np.eye(3) * 1e-5)  # about the COM [kg m^2]

    def extents(self) -> np.ndarray:
        return trimesh.util.concatenate([p.trimesh() for p in self.pieces]).extents


def _pose(xyz: tuple[float, float, float] | list[float] = (0.0, 0.0, 0.0), axis: str | None = None,
          angle: float = 0.0) -> np.ndarray:
    """A pose: rotation by `angle` about the x, y or z axis, then a translation."""
    X = np.eye(4)
    if axis is not None:
        X = trimesh.transformations.rotation_matrix(angle, np.eye(3)["xyz".index(axis)])
    X[:3, 3] = xyz
    return X


# -- the families -------------------------------------------------------------------------------
def _width(rng: np.random.Generator, low: float = 0.012) -> float:
    return float(rng.uniform(low, MAX_GRASP_WIDTH))


def _box(rng: np.random.Generator) -> list[Piece]:
    return [Piece("box", (_width(rng), rng.uniform(0.02, 0.15), rng.uniform(0.01, 0.12)))]


def _cylinder(rng: np.random.Generator) -> list[Piece]:
    return [Piece("cylinder", (_width(rng) / 2, rng.uniform(0.02, 0.15)))]


def _sphere(rng: np.random.Generator) -> list[Piece]:
    return [Piece("sphere", (_width(rng, 0.02) / 2,))]


def _capsule(rng: np.random.Generator) -> list[Piece]:
    return [Piece("capsule", (_width(rng) / 2, rng.uniform(0.01, 0.075)))]


def _l_shape(rng: np.random.Generator) -> list[Piece]:
    t, depth = rng.uniform(0.01, 0.035), _width(rng, 0.015)
    a, b = rng.uniform(0.04, 0.13, size=2)
    return [Piece("box", (a, depth, t), _pose((a / 2, 0, t / 2))),
            Piece("box", (t, depth, b), _pose((t / 2, 0, b / 2)))]


def _t_shape(rng: np.random.Generator) -> list[Piece]:
    t, depth = rng.uniform(0.01, 0.035), _width(rng, 0.015)
    a, b = rng.uniform(0.05, 0.14), rng.uniform(0.03, 0.12)
    return [Piece("box", (a, depth, t), _pose((0, 0, b + t / 2))),
            Piece("box", (t, depth, b), _pose((0, 0, b / 2)))]


def _mug(rng: np.random.Generator) -> list[Piece]:
    radius, height = rng.uniform(0.022, 0.034), rng.uniform(0.05, 0.12)  # the staves reach 2-3 mm beyond
    wall = rng.uniform(0.004, 0.008)
    pieces = [Piece("cylinder", (radius, wall), _pose((0, 0, wall / 2))),
              *_staves(radius, radius, height, wall, 10, 0.0)]
    return pieces + _handle(rng, radius, height, span=(0.3, 0.6), bar=(0.006, 0.012))


def _handle(rng: np.random.Generator, radius: float, height: float, *, span: tuple[float, float],
            bar: tuple[float, float]) -> list[Piece]:
    """A mug's handle of three bars on its +x side, 80 % of the time (else none): its reach 2-3.5 cm and
    its span (a fraction of the mug's height) and bar thickness drawn from the ranges given."""
    if rng.uniform() >= 0.8:
        return []
    reach, length, thickness = rng.uniform(0.02, 0.035), rng.uniform(*span) * height, rng.uniform(*bar)
    z0 = height / 2
    return [Piece("box", (thickness, thickness, length), _pose((radius + reach, 0, z0))),
            Piece("box", (reach, thickness, thickness), _pose((radius + reach / 2, 0, z0 + length / 2))),
            Piece("box", (reach, thickness, thickness), _pose((radius + reach / 2, 0, z0 - length / 2)))]


def _bottle(rng: np.random.Generator) -> list[Piece]:
    radius, body = _width(rng, 0.03) / 2, rng.uniform(0.05, 0.09)
    neck_r, neck = rng.uniform(0.008, min(0.015, radius * 0.6)), rng.uniform(0.02, 0.035)
    shoulder = rng.uniform(0.01, 0.025)
    return [Piece("cylinder", (radius, body), _pose((0, 0, body / 2))),
            Piece("mesh", mesh=_frustum(radius, neck_r, shoulder, body)),
            Piece("cylinder", (neck_r, neck), _pose((0, 0, body + shoulder + neck / 2)))]


def _stepped_bottle(rng: np.random.Generator) -> list[Piece]:
    """A bottle or can whose body steps straight to a narrower neck (no shoulder), half of them capped
    wider than the neck: lying down, the camera sees body and neck apart, a step between them."""
    radius = _width(rng, 0.03) / 2
    neck_r, neck = max(0.006, rng.uniform(0.3, 0.65) * radius), rng.uniform(0.015, 0.05)
    cap_r, cap = min(radius * 0.9, neck_r * rng.uniform(1.1, 1.4)), rng.uniform(0.008, 0.02)
    capped = rng.uniform() < 0.5
    body = min(rng.uniform(0.06, 0.13), MAX_EXTENT - neck - (cap if capped else 0.0))
    pieces = [Piece("cylinder", (radius, body), _pose((0, 0, body / 2))),
              Piece("cylinder", (neck_r, neck), _pose((0, 0, body + neck / 2)))]
    if capped:
        pieces.append(Piece("cylinder", (cap_r, cap), _pose((0, 0, body + neck + cap / 2))))
    return pieces


def _tool(rng: np.random.Generator) -> list[Piece]:
    handle_r, handle = rng.uniform(0.008, 0.02), rng.uniform(0.06, 0.10)
    head = (rng.uniform(0.02, 0.05), rng.uniform(0.05, 0.12), rng.uniform(0.02, 0.04))
    return [Piece("cylinder", (handle_r, handle), _pose((0, 0, 0), "x", math.pi / 2)),
            Piece("box", head, _pose((0, handle / 2 + head[0] / 2, 0), "z", math.pi / 2))]


def coarse_hull(points: np.ndarray, max_vertices: int = MAX_HULL_VERTICES) -> trimesh.Trimesh:
    """The convex hull of points, of at most `max_vertices` vertices: a hull with more is replaced by the
    hull of that many of its vertices, farthest-point sampled (from the one farthest from the centroid)."""
    return _coarsened(hull_mesh(points), max_vertices)


def _coarsened(hull: trimesh.Trimesh, max_vertices: int = MAX_HULL_VERTICES) -> trimesh.Trimesh:
    vertices = np.asarray(hull.vertices)
    if len(vertices) <= max_vertices:
        return hull
    chosen = [int(np.argmax(np.linalg.norm(vertices - vertices.mean(axis=0), axis=1)))]
    gap = np.linalg.norm(vertices - vertices[chosen[0]], axis=1)
    while len(chosen) < max_vertices:
        chosen.append(int(np.argmax(gap)))
        gap = np.minimum(gap, np.linalg.norm(vertices - vertices[chosen[-1]], axis=1))
    return hull_mesh(vertices[chosen])


def _frustum(r0: float, r1: float, height: float, z0: float) -> trimesh.Trimesh:
    angles = np.linspace(0, 2 * math.pi, 24, endpoint=False)
    ring = np.column_stack([np.cos(angles), np.sin(angles)])
    points = np.vstack([np.column_stack([r0 * ring, np.full(24, z0)]),
                        np.column_stack([r1 * ring, np.full(24, z0 + height)])])
    return hull_mesh(points)


def _superquadric(rng: np.random.Generator) -> list[Piece]:
    a = np.array([_width(rng) / 2, rng.uniform(0.01, 0.07), rng.uniform(0.01, 0.06)])
    e1, e2 = rng.uniform(0.3, 2.2, size=2)  # above 1: pinched (concave), below: boxy
    u, v = np.meshgrid(np.linspace(-math.pi / 2, math.pi / 2, 20), np.linspace(-math.pi, math.pi, 32),
                       indexing="ij")

    def spow(x, p):
        return np.sign(x) * np.abs(x) ** p

    x = a[0] * spow(np.cos(u), e1) * spow(np.cos(v), e2)
    y = a[1] * spow(np.cos(u), e1) * spow(np.sin(v), e2)
    z = a[2] * spow(np.sin(u), e1)
    return _grid_mesh(np.stack([x, y, z], axis=-1))


def _grid_mesh(points: np.ndarray) -> list[Piece]:
    """A closed mesh from an (rows, columns, 3) grid, rows from pole to pole, columns around."""
    rows, cols, _ = points.shape
    vertices = points.reshape(-1, 3)
    faces = []
    for i in range(rows - 1):
        for j in range(cols):
            a, b = i * cols + j, i * cols + (j + 1) % cols
            c, d = a + cols, b + cols
            faces += [[a, b, d], [a, d, c]]
    mesh = trimesh.Trimesh(vertices, np.array(faces), process=True)
    mesh.merge_vertices()
    mesh.update_faces(mesh.nondegenerate_faces())
    return [Piece("mesh", mesh=outward(mesh))]


def _extrusion(rng: np.random.Generator) -> list[Piece]:
    n = int(rng.integers(5, 10))
    angles = np.sort(rng.uniform(0, 2 * math.pi, n))
    radii = rng.uniform(0.4, 1.0, n) * rng.uniform(0.02, 0.07)
    outline = np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])
    height = _width(rng, 0.01)  # the extrusion's thickness is graspable
    bottom, top = np.column_stack([outline, np.zeros(n)]), np.column_stack([outline, np.full(n, height)])
    vertices = np.vstack([bottom, top, [[0, 0, 0], [0, 0, height]]])
    faces = []
    for i in range(n):  # a star-shaped outline: fans from the centre, quads around
        j = (i + 1) % n
        faces += [[2 * n, j, i], [2 * n + 1, n + i, n + j], [i, j, n + j], [i, n + j, n + i]]
    return [Piece("mesh", mesh=outward(trimesh.Trimesh(vertices, np.array(faces), process=True)))]


def _revolution(rng: np.random.Generator) -> list[Piece]:
    z = np.linspace(0, rng.uniform(0.04, 0.15), 12)
    knots = rng.uniform(0.3, 1.0, 4) * _width(rng, 0.02) / 2
    r = np.interp(z, np.linspace(z[0], z[-1], 4), knots)
    angles = np.linspace(0, 2 * math.pi, 24, endpoint=False)
    ring = np.stack([np.outer(r, np.cos(angles)), np.outer(r, np.sin(angles)), np.repeat(z[:, None], 24, 1)],
                    axis=-1)
    caps = [np.repeat([[[0.0, 0.0, z[0]]]], 24, 1), np.repeat([[[0.0, 0.0, z[-1]]]], 24, 1)]
    return _grid_mesh(np.concatenate([caps[0], ring, caps[1]], axis=0))


def _hull(rng: np.random.Generator) -> list[Piece]:
    scale = np.array([_width(rng) / 2, rng.uniform(0.01, 0.07), rng.uniform(0.01, 0.06)])
    points = rng.normal(size=(int(rng.integers(8, 30)), 3))
    points = points / np.linalg.norm(points, axis=1, keepdims=True) * rng.uniform(0.5, 1.0, (len(points), 1))
    return [Piece("mesh", mesh=hull_mesh(points * scale))]


# -- household objects at their real sizes -------------------------------------------------------
def _pack(rng: np.random.Generator) -> list[Piece]:
    """A small carton standing on its end: tea, spices, toothpaste, a deck of cards."""
    t, h = rng.uniform(0.025, 0.07), rng.uniform(0.06, 0.2)
    return [Piece("box", (t, rng.uniform(max(t, 0.05), 0.11), h), _pose((0, 0, h / 2)))]


def _carton(rng: np.random.Generator) -> list[Piece]:
    """A big box standing on its end: crackers, cereal, a shoe box; its broad faces wider than the hand."""
    t, h = rng.uniform(0.045, 0.11), rng.uniform(0.14, 0.32)
    return [Piece("box", (t, rng.uniform(0.12, 0.24), h), _pose((0, 0, h / 2)))]


def _can(rng: np.random.Generator) -> list[Piece]:
    radius, height = rng.uniform(0.026, 0.052), rng.uniform(0.05, 0.17)
    return [Piece("cylinder", (radius, height), _pose((0, 0, height / 2)))]


def _jar(rng: np.random.Generator) -> list[Piece]:
    radius, body = rng.uniform(0.03, 0.058), rng.uniform(0.06, 0.15)
    lid_r, lid = radius * rng.uniform(0.8, 1.03), rng.uniform(0.01, 0.025)
    return [Piece("cylinder", (radius, body), _pose((0, 0, body / 2))),
            Piece("cylinder", (lid_r, lid), _pose((0, 0, body + lid / 2)))]


def _jug(rng: np.random.Generator) -> list[Piece]:
    """A bottle at its real size: water, detergent, ketchup (body, shoulder, neck, cap)."""
    radius, body = rng.uniform(0.025, 0.055), rng.uniform(0.1, 0.22)
    neck_r, neck = rng.uniform(0.011, min(0.02, radius * 0.6)), rng.uniform(0.015, 0.05)
    shoulder = rng.uniform(0.015, 0.05)
    cap_r, cap = neck_r * rng.uniform(1.0, 1.3), rng.uniform(0.01, 0.025)
    top = body + shoulder + neck
    return [Piece("cylinder", (radius, body), _pose((0, 0, body / 2))),
            Piece("mesh", mesh=_frustum(radius, neck_r, shoulder, body)),
            Piece("cylinder", (neck_r, neck), _pose((0, 0, body + shoulder + neck / 2))),
            Piece("cylinder", (cap_r, cap), _pose((0, 0, top + cap / 2)))]


def _staves(r_bottom: float, r_top: float, height: float, wall: float, staves: int, z0: float) -> list[Piece]:
    """A thin wall of `staves` boxes around the z axis, from radius r_bottom at z0 to r_top at z0 + height."""
    tilt = math.atan2(r_top - r_bottom, height)
    length = math.hypot(height, r_top - r_bottom)
    width = 2 * max(r_bottom, r_top) * math.tan(math.pi / staves) + wall
    pieces = []
    for k in range(staves):
        a = 2 * math.pi * k / staves
        r_mid = (r_bottom + r_top) / 2 - wall / 2 * math.cos(tilt)
        X = _pose((0, 0, 0), "z", a) @ _pose((0, 0, 0), "y", tilt)
        X[:3, 3] = [r_mid * math.cos(a), r_mid * math.sin(a), z0 + height / 2]
        pieces.append(Piece("box", (wall, width, length), X))
    return pieces


def _bowl(rng: np.random.Generator) -> list[Piece]:
    """A bowl: a foot disc and a flaring wall; the hand takes it by the rim."""
    r_top, height, wall = rng.uniform(0.055, 0.095), rng.uniform(0.04, 0.08), rng.uniform(0.004, 0.008)
    r_bottom = r_top * rng.uniform(0.45, 0.7)
    return [Piece("cylinder", (r_bottom, wall), _pose((0, 0, wall / 2))),
            *_staves(r_bottom, r_top, height, wall, 12, 0.0)]


def _plate(rng: np.random.Generator) -> list[Piece]:
    """A plate or a lid: a thin disc wider than the hand, with a low rim on most."""
    radius, thickness = rng.uniform(0.07, 0.13), rng.uniform(0.006, 0.015)
    pieces = [Piece("cylinder", (radius, thickness), _pose((0, 0, thickness / 2)))]
    if rng.uniform() < 0.7:
        pieces += _staves(radius * 0.92, radius, rng.uniform(0.01, 0.025), thickness, 12, thickness)
    return pieces


def _household_mug(rng: np.random.Generator) -> list[Piece]:
    """A mug or cup at its real size (7-10 cm across), most with a handle."""
    radius, height, wall = rng.uniform(0.035, 0.05), rng.uniform(0.07, 0.12), rng.uniform(0.004, 0.007)
    pieces = [Piece("cylinder", (radius, wall), _pose((0, 0, wall / 2))),
              *_staves(radius, radius, height, wall, 10, 0.0)]
    return pieces + _handle(rng, radius, height, span=(0.4, 0.7), bar=(0.008, 0.014))


def _hammer(rng: np.random.Generator) -> list[Piece]:
    """A hammer or mallet lying on the table: a long handle and a heavy head."""
    handle_r, handle = rng.uniform(0.01, 0.018), rng.uniform(0.18, 0.3)
    head = (rng.uniform(0.025, 0.045), rng.uniform(0.08, 0.13), rng.uniform(0.025, 0.045))
    return [Piece("cylinder", (handle_r, handle), _pose((0, 0, 0), "x", math.pi / 2)),
            Piece("box", head, _pose((0, handle / 2 + head[0] / 2, 0), "z", math.pi / 2))]


def _screwdriver(rng: np.random.Generator) -> list[Piece]:
    """A screwdriver, a marker or a brush lying down: a grip and a thin shaft along y."""
    grip_r, grip = rng.uniform(0.011, 0.02), rng.uniform(0.08, 0.12)
    shaft_r, shaft = rng.uniform(0.003, 0.006), rng.uniform(0.06, 0.15)
    return [Piece("cylinder", (grip_r, grip), _pose((0, 0, 0), "x", math.pi / 2)),
            Piece("cylinder", (shaft_r, shaft), _pose((0, grip / 2 + shaft / 2, 0), "x", math.pi / 2))]


def _ball(rng: np.random.Generator) -> list[Piece]:
    """A toy ball, a softball, a grapefruit: 5-11 cm across."""
    return [Piece("sphere", (rng.uniform(0.025, 0.055),))]


def _toy_car(rng: np.random.Generator) -> list[Piece]:
    """A toy car: a body on four wheels, a cabin on top."""
    length, width, height = rng.uniform(0.08, 0.16), rng.uniform(0.04, 0.08), rng.uniform(0.02, 0.04)
    wheel_r = rng.uniform(0.01, 0.018)
    z = wheel_r + height / 2
    pieces = [Piece("box", (length, width, height), _pose((0, 0, z)))]
    cabin = (length * rng.uniform(0.4, 0.6), width * 0.9, height * rng.uniform(0.6, 1.0))
    pieces.append(Piece("box", cabin, _pose((0, 0, z + height / 2 + cabin[2] / 2))))
    for sx in (-1, 1):
        for sy in (-1, 1):
            X = _pose((sx * length * 0.32, sy * (width / 2 + 0.006), wheel_r), "x", math.pi / 2)
            pieces.append(Piece("cylinder", (wheel_r, 0.012), X))
    return pieces


def _shoe(rng: np.random.Generator) -> list[Piece]:
    """A shoe: a sole 22-30 cm long and a rounded upper, wider than the hand but for its heel and collar."""
    length, width, sole = rng.uniform(0.22, 0.3), rng.uniform(0.08, 0.11), rng.uniform(0.02, 0.035)
    upper_h = rng.uniform(0.05, 0.1)
    points = []
    for x in np.linspace(-length / 2, length / 2, 7):
        taper = 1.0 - 0.6 * max(0.0, x / (length / 2)) ** 2  # lower toward the toe
        for y in (-width / 2, width / 2):
            points += [(x, y * 0.9, sole), (x, y * 0.8, sole + upper_h * taper)]
    return [Piece("box", (length, width, sole), _pose((0, 0, sole / 2))),
            Piece("mesh", mesh=hull_mesh(np.array(points)))]


def _fruit(rng: np.random.Generator) -> list[Piece]:
    """An apple, a lemon, a pear, a potato: a lumpy round hull 5-10 cm long."""
    axes = np.array([rng.uniform(0.025, 0.05), rng.uniform(0.022, 0.04), rng.uniform(0.022, 0.04)])
    points = rng.normal(size=(60, 3))
    points = points / np.linalg.norm(points, axis=1, keepdims=True) * rng.uniform(0.85, 1.0, (60, 1))
    return [Piece("mesh", mesh=hull_mesh(points * axes))]


HOUSEHOLD_FAMILIES = ("pack", "carton", "can", "jar", "jug", "bowl", "plate", "household_mug", "hammer",
                      "screwdriver", "ball", "toy_car", "shoe", "fruit")
# Their density [kg/m^3] over the solid volume of their pieces (the rest: DENSITY_RANGE).
HOUSEHOLD_DENSITY = {"pack": (150.0, 700.0), "carton": (80.0, 400.0), "can": (400.0, 1100.0),
                     "jar": (400.0, 1100.0), "jug": (200.0, 900.0), "bowl": (800.0, 1600.0),
                     "plate": (800.0, 1600.0), "household_mug": (1000.0, 2000.0),
                     "hammer": (900.0, 3000.0), "screwdriver": (700.0, 1500.0), "ball": (80.0, 600.0),
                     "toy_car": (200.0, 900.0), "shoe": (150.0, 450.0), "fruit": (700.0, 1000.0)}


COMPOSITIONS = ("l_shape", "t_shape", "mug", "bottle", "tool", "stepped_bottle")


def rests_graspable(family: str, pieces: list[Piece]) -> bool:
    """Whether the hand can close across the object in each of its resting poses.

    A composition offers the widths of its parts; a solid lying on its broad face shows the hand
    its two larger extents, so the middle one must fit the stroke. The solids are drawn along
    the object frame's axes, so its axis-aligned extents are theirs (an upper bound otherwise).
    """
    if family in COMPOSITIONS or family in HOUSEHOLD_FAMILIES:  # (household objects: at their real sizes)
        return True
    points = np.vstack([p.trimesh().vertices for p in pieces])
    return float(np.sort(np.ptp(points, axis=0))[1]) <= MAX_GRASP_WIDTH


MAKERS = {"box": _box, "cylinder": _cylinder, "sphere": _sphere, "capsule": _capsule, "l_shape": _l_shape,
          "t_shape": _t_shape, "mug": _mug, "bottle": _bottle, "tool": _tool, "superquadric": _superquadric,
          "extrusion": _extrusion, "revolution": _revolution, "hull": _hull,
          "stepped_bottle": _stepped_bottle, "pack": _pack, "carton": _carton, "can": _can, "jar": _jar,
          "jug": _jug, "bowl": _bowl, "plate": _plate, "household_mug": _household_mug, "hammer": _hammer,
          "screwdriver": _screwdriver, "ball": _ball, "toy_car": _toy_car, "shoe": _shoe, "fruit": _fruit}


# -- one object -------------------------------------------------------------------------------
def convex_pieces(mesh: trimesh.Trimesh, *, seed: int = 0) -> list[trimesh.Trimesh]:
    """The mesh as convex pieces: itself if it nearly fills its hull, else CoACD's decomposition."""
    full_hull = hull_mesh(mesh.vertices)
    hull = _coarsened(full_hull)
    if mesh.is_watertight and mesh.volume >= CONVEX_VOLUME_RATIO * full_hull.volume:
        return [hull]
    import coacd

    coacd.set_log_level("error")
    parts = coacd.run_coacd(coacd.Mesh(mesh.vertices, mesh.faces), threshold=COACD_THRESHOLD,
                            max_convex_hull=COACD_MAX_PIECES, seed=seed)
    pieces = [coarse_hull(v) for v, _ in parts if len(v) >= 4]
    # CoACD can return slivers; Drake rejects a flat convex hull, and a sliver adds no contact.
    pieces = [p for p in pieces if p.volume > MIN_PIECE_VOLUME and p.extents.min() > MIN_PIECE_THICKNESS]
    return pieces or [hull]


def object_name(family: str, seed: int, k: int) -> str:
    """Names unique across corpora: `mug_s0_00001` is object 1 of corpus 0, a mug."""
    return f"{family}_s{seed}_{k:05d}"


def elongated(pieces: list[Piece], factor: float) -> list[Piece]:
    """The pieces stretched by `factor` along the object's longest axis-aligned extent, about its middle:
    each convex piece becomes the (coarse) hull of its stretched vertices, still convex."""
    meshes = [p.trimesh() for p in pieces]
    points = np.vstack([m.vertices for m in meshes])
    axis = int(np.argmax(np.ptp(points, axis=0)))
    middle = (points.max(axis=0) + points.min(axis=0)) / 2
    scale = np.ones(3)
    scale[axis] = factor
    return [Piece("mesh", mesh=coarse_hull((m.vertices - middle) * scale + middle)) for m in meshes]


def generate_object(seed: int, k: int, families: tuple[str, ...] = FAMILIES,
                    elongation: tuple[float, float] | None = None) -> GeneratedObject:
    """Object k of the corpus `seed`: its family, convex pieces, mass properties, friction and colour;
    with `elongation` (low, high), stretched along its longest extent by a factor drawn from it."""
    rng = np.random.default_rng([seed, k])
    family = families[int(rng.integers(len(families)))]
    for _ in range(MAX_REDRAWS):  # the same stream: an object that fits on its first draw is unchanged
        drawn = MAKERS[family](rng)
        if rests_graspable(family, drawn):
            break
    else:
        name = object_name(family, seed, k)
        raise RuntimeError(f"{name}: none of {MAX_REDRAWS} draws is graspable lying flat")
    pieces = []
    for piece in drawn:
        if piece.kind == "mesh":
            pieces += [Piece("mesh", mesh=m) for m in convex_pieces(piece.mesh, seed=seed * 100_003 + k)]
        else:
            pieces.append(piece)
    household = family in HOUSEHOLD_FAMILIES
    density = rng.uniform(*HOUSEHOLD_DENSITY.get(family, DENSITY_RANGE))
    rgba = (*rng.uniform(0.2, 0.95, 3), 1.0)
    friction = float(rng.uniform(*FRICTION_RANGE))
    if elongation is not None:
        pieces = elongated(pieces, float(np.random.default_rng([seed, k, 1]).uniform(*elongation)))
    mass, p_OScm, I_SScm_O = mass_properties(pieces, density,
                                             mass_range=HOUSEHOLD_MASS_RANGE if household else MASS_RANGE)
    return GeneratedObject(object_name(family, seed, k), family, pieces, mass, friction,
                           tuple(float(c) for c in rgba), p_OScm, I_SScm_O)


def mass_properties(pieces: list[Piece], density: float | None = None, *, mass: float | None = None,
                    mass_range: tuple[float, float] = MASS_RANGE) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass, centre of mass p_OScm, inertia about it I_SScm_O) of the pieces, from a density (the mass
    clipped to `mass_range`) or a given mass. Pieces' overlaps count twice: a fair estimate."""
    whole = trimesh.util.concatenate([p.trimesh() for p in pieces])
    unit = whole.mass_properties  # at unit density
    if mass is None:
        mass = float(np.clip(unit["mass"] * density, *mass_range))
    scale = mass / max(unit["mass"], 1e-12)
    return mass, np.asarray(unit["center_mass"]), np.asarray(unit["inertia"]) * scale


def _primitive_geometry(piece: Piece) -> str:
    s = piece.size
    if piece.kind == "box":
        return f"<box><size>{s[0]:.5f} {s[1]:.5f} {s[2]:.5f}</size></box>"
    if piece.kind == "sphere":
        return f"<sphere><radius>{s[0]:.5f}</radius></sphere>"
    return f"<{piece.kind}><radius>{s[0]:.5f}</radius><length>{s[1]:.5f}</length></{piece.kind}>"


def write_sdf(obj: GeneratedObject, folder: Path) -> Path:
    """The object as an SDF (one link, a collision and a visual per piece), its meshes as OBJ files in
    `folder/meshes/` (where an object set does not take them for objects of their own); the SDF is
    written last, so an interrupted write leaves no object behind."""
    (folder / MESH_FOLDER).mkdir(parents=True, exist_ok=True)
    props = dc.replace(OBJECT_CONTACT, resolution_hint=MESH_RESOLUTION_HINT).sdf_tags(obj.friction)
    color = " ".join(f"{c:.3f}" for c in obj.rgba)
    blocks = []
    for i, piece in enumerate(obj.pieces):
        if piece.kind == "mesh":
            mesh_file = f"{MESH_FOLDER}/{obj.name}_{i:02d}.obj"
            piece.mesh.export(folder / mesh_file)
            geometry, pose = f"<mesh><uri>{mesh_file}</uri><drake:declare_convex/></mesh>", "0 0 0 0 0 0"
        else:
            geometry = _primitive_geometry(piece)
            rpy = trimesh.transformations.euler_from_matrix(piece.X, "sxyz")
            pose = " ".join(f"{v:.6f}" for v in (*piece.X[:3, 3], *rpy))
        blocks.append(f"<collision name='c{i}'><pose>{pose}</pose><geometry>{geometry}</geometry>{props}"
                      f"</collision><visual name='v{i}'><pose>{pose}</pose><geometry>{geometry}</geometry>"
                      f"<material><diffuse>{color}</diffuse></material></visual>")
    I = obj.inertia  # noqa: E741
    com = " ".join(f"{c:.6f}" for c in obj.com)
    text = ("<?xml version='1.0'?>\n<sdf version='1.9' xmlns:drake='http://drake.mit.edu'>\n"
            f"<model name='{obj.name}'><link name='{obj.name}'>\n"
            f"<inertial><pose>{com} 0 0 0</pose><mass>{obj.mass:.5f}</mass><inertia>"
            f"<ixx>{I[0, 0]:.4e}</ixx><ixy>{I[0, 1]:.4e}</ixy><ixz>{I[0, 2]:.4e}</ixz>"
            f"<iyy>{I[1, 1]:.4e}</iyy><iyz>{I[1, 2]:.4e}</iyz><izz>{I[2, 2]:.4e}</izz></inertia></inertial>\n"
            + "\n".join(blocks) + "\n</link></model></sdf>\n")
    path = folder / f"{obj.name}.sdf"
    partial = folder / f"{obj.name}.sdf.partial"
    partial.write_text(text)
    partial.replace(path)
    return path
