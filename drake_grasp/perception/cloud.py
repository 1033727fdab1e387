"""Object point cloud from the cameras' world-frame cloud (paper Alg. 1, line 1).

Crop to the camera's workspace and remove the table with a seeded RANSAC plane fit
(the paper's PlanarSegmentation), refined by least squares; the table's own scatter about the
plane sets how far above it a point must lie to be an object (a real sensor's table is a few
millimetres thick), and specks left above it (isolated points) go. A scene may hold more than
objects (a shelf, a stool):
with `PerceptionConfig.structure_extent` the segments wider than that are scene structure,
kept apart from the objects (no grasp candidates on them, but in the CNN's input and the
planning world), and with `PerceptionConfig.free_space` the cloud carries its cameras'
rays, the space each camera saw through. Pure functions on (N, 3) arrays;
`ObjectCloudSystem` wraps them for the diagram.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import open3d as o3d
from pydrake.common.value import Value
from pydrake.perception import PointCloud
from pydrake.systems.framework import LeafSystem

from drake_grasp.perception.config import PerceptionConfig
from drake_grasp.robot.stages import stage

PLANE_DISTANCE = 0.004  # RANSAC inlier threshold, and the least margin above the table [m]
# The margin above the table is this quantile of the table's points' depths below the plane (the table's
# scatter is symmetric about it; objects lie only above), within [PLANE_DISTANCE, MAX_TABLE_MARGIN].
TABLE_MARGIN_QUANTILE = 0.999
MAX_TABLE_MARGIN = 0.015  # [m] a flatter object than this would vanish with the table
TABLE_BAND = 0.02  # [m] points this near the RANSAC plane are the table's, for its refit and scatter
MIN_TABLE_POINTS = 500  # fewer points below the plane than this: the margin is PLANE_DISTANCE
# With the camera's position known, the margin grows with the distance from it as the sensor's noise does:
# the table points below the plane are split in this many bins of equal count by their distance, each
# bin's quantile is its margin, interpolated between the bins' median distances.
RANGE_BINS = 6
# Specks: an object point with fewer than SPECK_NEIGHBOURS others within SPECK_SPACINGS times the object
# cloud's median point spacing (at least SPECK_RADIUS) is a speck of sensor noise, not an object.
SPECK_NEIGHBOURS = 4
SPECK_SPACINGS = 3.0
SPECK_RADIUS = 0.006  # [m]
RANSAC_ITERATIONS = 200
RANSAC_SCORED = 16_384  # points a RANSAC plane is scored on (a seeded sample of a larger cloud)
RANSAC_CHUNK = 2048  # scored points a block
MIN_OBJECT_POINTS = 30  # fewer points than this after segmentation means "no objects"
SEGMENT_GAP = 0.008  # [m] object points closer than this are one object (the camera's are 2-3 mm apart)
SEGMENT_MIN_POINTS = 5  # DBSCAN's core-point neighbourhood
# `join_end_to_end`: a part continues a body when it lies on the body's long axis (its centroid this near
# the axis line), begins where the body ends (overlapping it along the axis by at most END_OVERLAP), is
# narrower and lower, and comes this near it (the step between a lying bottle's body and neck).
COAXIAL_TOLERANCE = 0.005  # [m]
END_OVERLAP = 0.01  # [m]
END_JOIN_GAP = 0.03  # [m]
JOINED_MIN_POINTS = 30  # segments smaller than this are left as they are


STRUCTURE_JOIN_GAP = 0.03  # [m] a segment this near scene structure is part of it
MAX_RAYS = 20_000  # camera rays kept for the free space (an even subsample of the cropped cloud)


class PerceptionError(ValueError):
    """Input the perception pipeline cannot use (empty or non-finite cloud)."""


@dataclass
class ObjectCloud:
    """Object points in the world frame (table removed), the table top's height under them, and what else
    the cameras saw (`PerceptionConfig`)."""

    points: np.ndarray  # (N, 3) the objects' points
    table_z: float | None = None  # the segmented table plane's z under the objects' centre; None: not seen
    structure: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (K, 3) scene structure
    # (origins (V, 3), ends (V, 3)): camera rays to what they hit (the table included); None: not kept
    rays: tuple[np.ndarray, np.ndarray] | None = None
    table: TablePlane | None = None  # the fitted table plane; None: not seen

    def __len__(self) -> int:
        return len(self.points)

    @property
    def scene_points(self) -> np.ndarray:
        """The objects' points and the structure's: what a grasp's voxel grid sees."""
        return np.vstack([self.points, self.structure]) if len(self.structure) else self.points

    @staticmethod
    def empty() -> ObjectCloud:
        return ObjectCloud(np.zeros((0, 3)))


def crop(points: np.ndarray, lower, upper) -> np.ndarray:
    """Finite points inside the axis-aligned box [lower, upper]."""
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise PerceptionError(f"point cloud must be (N, 3), got {points.shape}")
    lower, upper = np.broadcast_to(lower, 3), np.broadcast_to(upper, 3)
    keep = np.ones(len(points), dtype=bool)
    for axis in range(3):  # column by column: one pass over each, no (N, 3) temporaries
        column = points[:, axis]
        keep &= (column >= lower[axis]) & (column <= upper[axis])  # (NaN compares false)
    if not (np.isfinite(lower).all() and np.isfinite(upper).all()):
        keep &= np.isfinite(points).all(axis=1)
    return points[keep]


def fit_plane(points: np.ndarray, *, seed: int = 0) -> tuple[np.ndarray, float]:
    """The dominant plane n . p + d = 0 of a cloud (|n| = 1), by RANSAC.

    `RANSAC_ITERATIONS` planes through 3 points each are scored by their inliers (within
    `PLANE_DISTANCE`) among `RANSAC_SCORED` points of the cloud; the most wins. Every draw comes from
    `numpy.random.default_rng(seed)`, so the plane depends only on (points, seed). (open3d's
    `segment_plane` does not: seeded the same way, it found two different table planes for one
    camera cloud in successive calls, and the object cloud differed by 12 % of its points.)
    """
    rng = np.random.default_rng(seed)
    scored = points if len(points) <= RANSAC_SCORED else points[rng.integers(0, len(points), RANSAC_SCORED)]
    p0, p1, p2 = scored[rng.integers(0, len(scored), (3, RANSAC_ITERATIONS))]
    normals = np.cross(p1 - p0, p2 - p0)
    length = np.linalg.norm(normals, axis=1)
    degenerate = length < 1e-12
    normals = normals / np.where(degenerate, 1.0, length)[:, None]
    offsets = -(normals * p0).sum(axis=1)
    inliers = np.zeros(len(normals), dtype=np.int64)
    for start in range(0, len(scored), RANSAC_CHUNK):  # chunks that stay in cache
        distances = scored[start:start + RANSAC_CHUNK] @ normals.T
        distances += offsets
        inliers += (np.abs(distances, out=distances) <= PLANE_DISTANCE).sum(axis=0)
    best = int(np.argmax(np.where(degenerate, -1, inliers)))  # (the first of equals)
    return normals[best], float(offsets[best])


@dataclass(frozen=True)
class TablePlane:
    """The table top n . p + d = 0 (n up) and how far above it the objects begin."""

    normal: np.ndarray  # (3,) unit, z > 0
    offset: float
    margin: float  # points higher than this above the plane are objects (at the median range) [m]
    residual_rms: float  # the table points' RMS distance from the plane [m]
    inliers: int  # points within the margin of the plane
    # (viewpoint (3,), distances (B,), margins (B,)): the margin by distance from the camera; None: `margin`
    by_range: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def heights(self, points: np.ndarray) -> np.ndarray:
        """(N,) signed heights of points above the plane [m]."""
        return np.asarray(points, dtype=np.float64) @ self.normal + self.offset

    def margin_at(self, points: np.ndarray) -> np.ndarray | float:
        """The margin above the table at each point (one number without `by_range`) [m]."""
        if self.by_range is None:
            return self.margin
        viewpoint, distances, margins = self.by_range
        return np.interp(np.linalg.norm(np.asarray(points) - viewpoint, axis=1), distances, margins)

    def z_at(self, x: float, y: float) -> float:
        """The plane's z at (x, y)."""
        return float(-(self.offset + self.normal[0] * x + self.normal[1] * y) / self.normal[2])


def refine_plane(points: np.ndarray, normal: np.ndarray, offset: float,
                 band: float = PLANE_DISTANCE) -> tuple[np.ndarray, float]:
    """The least-squares plane of the points within `band` of (normal, offset), facing the same way."""
    near = points[np.abs(points @ normal + offset) <= band]
    if len(near) < 3:
        return normal, offset
    centre = near.mean(axis=0)
    refined = np.linalg.svd(near - centre, full_matrices=False)[2][2]
    refined = refined * (1.0 if refined @ normal >= 0 else -1.0)
    return refined, float(-refined @ centre)


def fit_table(points: np.ndarray, *, seed: int = 0, viewpoint: np.ndarray | None = None) -> TablePlane | None:
    """The table plane of a cropped cloud (`fit_plane`, refined on its inliers), or None when the dominant
    plane is not horizontal. Its margin is the table's scatter below the plane (`TABLE_MARGIN_QUANTILE`),
    by distance from the camera at `viewpoint` when that is given (`RANGE_BINS`); a flat, noiseless table
    gets `PLANE_DISTANCE`."""
    return _fit_table(points, seed, viewpoint)[0]


def _fit_table(points: np.ndarray, seed: int, viewpoint: np.ndarray | None,
               ) -> tuple[TablePlane | None, np.ndarray | None, np.ndarray | float | None]:
    """`fit_table`'s plane, with each point's height above it and the margin there (None without one)."""
    if len(points) < 3:
        return None, None, None
    normal, offset = fit_plane(points, seed=seed)
    if abs(normal[2]) < 0.9:
        return None, None, None
    sign = np.sign(normal[2])
    normal, offset = refine_plane(points, normal * sign, offset * sign)
    heights = points @ normal + offset
    low = (heights < 0) & (heights > -TABLE_BAND)
    below = -heights[low]
    margin, by_range = PLANE_DISTANCE, None
    if len(below) >= MIN_TABLE_POINTS:
        margin = _scatter_margin(below)
        if viewpoint is not None and len(below) >= MIN_TABLE_POINTS * RANGE_BINS:
            viewpoint = np.asarray(viewpoint, dtype=np.float64)
            distance = np.linalg.norm(points[low] - viewpoint, axis=1)
            bins = np.array_split(np.argsort(distance), RANGE_BINS)
            by_range = (viewpoint, np.array([np.median(distance[b]) for b in bins]),
                        np.array([_scatter_margin(below[b]) for b in bins]))
            margin = float(np.interp(np.median(distance), by_range[1], by_range[2]))
    plane = TablePlane(normal, offset, margin, 0.0, 0, by_range)
    margins = plane.margin_at(points)
    table = np.abs(heights) <= margins
    rms = float(np.sqrt(np.mean(heights[table] ** 2))) if table.any() else 0.0
    return dataclasses.replace(plane, residual_rms=rms, inliers=int(table.sum())), heights, margins


def _scatter_margin(below: np.ndarray) -> float:
    return float(np.clip(np.quantile(below, TABLE_MARGIN_QUANTILE), PLANE_DISTANCE, MAX_TABLE_MARGIN))


def remove_table(points: np.ndarray, *, seed: int = 0) -> tuple[np.ndarray, float | None]:
    """Drops the table (`fit_table`: the points within its margin, and those below it: noise or the
    table's edge) when the dominant plane is horizontal; returns the points left and the plane's height
    under their centre (None when no table plane was found). The result depends only on (points, seed)."""
    objects, table_z, _ = _split_table(points, seed)
    return objects, table_z


def _split_table(points: np.ndarray, seed: int, viewpoint: np.ndarray | None = None,
                 ) -> tuple[np.ndarray, float | None, TablePlane | None]:
    table, heights, margins = _fit_table(points, seed, viewpoint)
    if table is None:
        return points, None, None
    objects = points[heights > margins]
    x, y = (objects if len(objects) else points)[:, :2].mean(axis=0)
    return objects, table.z_at(x, y), table


def remove_specks(points: np.ndarray) -> np.ndarray:
    """The points less their specks: open3d's radius outlier filter, at a radius of `SPECK_SPACINGS` times
    the cloud's median nearest-neighbour spacing (at least `SPECK_RADIUS`), so that it scales with the
    camera's resolution and distance."""
    if len(points) <= SPECK_NEIGHBOURS:
        return points
    cloud = _cloud(points)
    spacing = float(np.median(np.asarray(cloud.compute_nearest_neighbor_distance())))
    radius = max(SPECK_RADIUS, SPECK_SPACINGS * spacing)
    _, kept = cloud.remove_radius_outlier(nb_points=SPECK_NEIGHBOURS + 1, radius=radius)
    return points[np.sort(np.asarray(kept, dtype=np.int64))]


def segment_objects(points: np.ndarray, gap: float = SEGMENT_GAP) -> np.ndarray:
    """(N,) object labels of an object cloud: open3d's DBSCAN, points chained by gaps under `gap`
    (touching objects come out as one); -1 marks isolated noise points."""
    if len(points) == 0:
        return np.zeros(0, dtype=int)
    points = np.asarray(points, dtype=np.float64)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    return np.asarray(cloud.cluster_dbscan(eps=gap, min_points=SEGMENT_MIN_POINTS), dtype=int)


@dataclass(frozen=True)
class _Footprint:
    """A segment seen from above: centroid, long axis (unit, xy), extent along and width across it, top."""

    centroid: np.ndarray  # (2,)
    axis: np.ndarray  # (2,)
    along: tuple[float, float]
    width: float
    top: float

    @staticmethod
    def of(points: np.ndarray) -> _Footprint:
        centroid = points[:, :2].mean(axis=0)
        xy = points[:, :2] - centroid
        axis = np.linalg.eigh(xy.T @ xy)[1][:, 1]  # (eigenvalues ascending: the long axis is last)
        along, across = xy @ axis, xy @ [-axis[1], axis[0]]
        return _Footprint(centroid, axis, (float(along.min()), float(along.max())), float(np.ptp(across)),
                          float(points[:, 2].max()))

    def continued_by(self, part: np.ndarray, other: _Footprint) -> bool:
        """Whether the points `part` (footprint `other`) lie on this footprint's axis past one of its ends,
        narrower and lower."""
        r = other.centroid - self.centroid
        if abs(r[0] * self.axis[1] - r[1] * self.axis[0]) > COAXIAL_TOLERANCE:
            return False
        if other.width >= self.width or other.top >= self.top:
            return False
        along = (part[:, :2] - self.centroid) @ self.axis
        lo, hi = self.along
        return bool(along.min() >= hi - END_OVERLAP or along.max() <= lo + END_OVERLAP)


def join_end_to_end(points: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """`labels` (`segment_objects`) with each part that continues a larger segment end to end merged into
    it: the neck or cap of a lying bottle or can, which the camera sees apart from its body (a step between
    them), is one object with it; a neighbour beside a body or across its axis stays apart. A part joins
    the largest segment it continues (a chain, body-neck-cap, is one object)."""
    points = np.asarray(points, dtype=np.float64)
    labels = np.asarray(labels).copy()
    ids, counts = np.unique(labels[labels >= 0], return_counts=True)
    ids = [int(k) for k, n in sorted(zip(ids, counts, strict=True), key=lambda kn: -kn[1])
           if n >= JOINED_MIN_POINTS]
    parts = {k: points[labels == k] for k in ids}
    footprints = {k: _Footprint.of(parts[k]) for k in ids}
    joined = {}
    for i, body in enumerate(ids):
        for part in ids[i + 1:]:
            if part in joined or not footprints[body].continued_by(parts[part], footprints[part]):
                continue
            if _nearest_distance(parts[body], parts[part]) <= END_JOIN_GAP:
                joined[part] = body
    def root(k: int) -> int:
        return root(joined[k]) if k in joined else k

    for part in joined:
        labels[labels == part] = root(part)
    return labels


def _nearest_distance(a: np.ndarray, b: np.ndarray) -> float:
    """The smallest distance between a point of `a` (M, 3) and one of `b` (K, 3)."""
    tree = o3d.geometry.KDTreeFlann(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(a)))
    return float(np.sqrt(min(tree.search_knn_vector_3d(p, 1)[2][0] for p in b)))


def split_structure(points: np.ndarray, extent: float) -> tuple[np.ndarray, np.ndarray]:
    """(objects, structure): the points of segments whose footprint is longer than `extent` [m] are
    structure, and so is every segment that comes within `STRUCTURE_JOIN_GAP` of them (a leg's side the
    camera sees apart from its front); the rest, isolated noise points included, are objects."""
    labels = segment_objects(points)
    structure = np.zeros(len(points), dtype=bool)
    for k in np.unique(labels[labels >= 0]):
        members = labels == k
        if np.linalg.norm(np.ptp(points[members, :2], axis=0)) > extent:
            structure |= members
    if structure.any() and not structure.all():
        rest = np.flatnonzero(~structure)
        distance = np.asarray(_cloud(points[rest]).compute_point_cloud_distance(_cloud(points[structure])))
        near = rest[distance < STRUCTURE_JOIN_GAP]
        joined = np.isin(labels, np.unique(labels[near][labels[near] >= 0]))
        structure |= joined
        structure[near] = True
    return points[~structure], points[structure]


def _cloud(points: np.ndarray) -> o3d.geometry.PointCloud:
    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64)))


def camera_rays(points_W: np.ndarray, cameras: list[tuple[np.ndarray, int]], lower, upper,
                max_rays: int = MAX_RAYS) -> tuple[np.ndarray, np.ndarray]:
    """(origins, ends) of the rays from each camera to the points it saw inside [lower, upper].

    `points_W` is the cameras' clouds one after the other, each `(xyz, count)` camera's `count` points
    (one a pixel); an even subsample of at most `max_rays` is kept."""
    pixels = sum(count for _, count in cameras)
    if pixels != len(points_W):
        raise ValueError(f"the cloud has {len(points_W)} points, the cameras' images {pixels}")
    camera = np.repeat(np.arange(len(cameras)), [count for _, count in cameras])
    keep = np.isfinite(points_W).all(axis=1)
    keep[keep] = (points_W[keep] >= lower).all(axis=1) & (points_W[keep] <= upper).all(axis=1)
    ends, camera = points_W[keep], camera[keep]
    step = max(1, -(-len(ends) // max_rays))
    ends, camera = ends[::step], camera[::step]
    origins = np.asarray([xyz for xyz, _ in cameras], dtype=float).reshape(-1, 3)[camera]
    return origins, ends


@stage("perception")
def extract_object_cloud(points_W: np.ndarray, *, lower, upper, seed: int = 0,
                         config: PerceptionConfig | None = None,
                         cameras: list[tuple[np.ndarray, int]] | None = None,
                         viewpoint: np.ndarray | None = None) -> ObjectCloud:
    """Cropped, table-free object cloud (specks removed with `config.remove_specks`); empty when
    no objects remain. `viewpoint`, the position of the one camera that took the cloud, lets the margin
    above the table grow with the distance from it (`fit_table`).

    With `config.structure_extent`, scene structure is split off the objects; with `config.free_space`,
    the cameras (`camera_rays`: position and point count each, in the cloud's order) give its rays.
    Raises PerceptionError for an empty or entirely non-finite input cloud.
    """
    config = config or PerceptionConfig()
    points_W = np.asarray(points_W, dtype=np.float64)
    if points_W.size == 0:
        raise PerceptionError("the point cloud is empty")
    if not np.isfinite(points_W).any():
        raise PerceptionError("the point cloud has no finite point (NaN depth everywhere)")
    objects, table_z, table = _split_table(crop(points_W, lower, upper), seed, viewpoint)
    if config.remove_specks:
        objects = remove_specks(objects)
    structure = np.zeros((0, 3))
    if config.structure_extent > 0.0 and len(objects):
        objects, structure = split_structure(objects, config.structure_extent)
    if len(objects) < MIN_OBJECT_POINTS:
        return ObjectCloud.empty()
    rays = None
    if config.free_space:
        if cameras is None:
            raise ValueError("free space needs the cameras (position and point count) of the cloud")
        rays = camera_rays(points_W, cameras, lower, upper)
    return ObjectCloud(objects, table_z, structure, rays, table)


class ObjectCloudSystem(LeafSystem):
    """World-frame PointCloud in, `ObjectCloud` out (crop, table removal, structure and free space as
    `config` says; `cameras`: each camera's position and pixel count, in the cloud's order)."""

    def __init__(self, *, lower, upper, config: PerceptionConfig | None = None,
                 cameras: list[tuple[np.ndarray, int]] | None = None):
        super().__init__()
        self._lower, self._upper = np.asarray(lower), np.asarray(upper)
        self._config, self._cameras = config or PerceptionConfig(), cameras
        self._cloud_port = self.DeclareAbstractInputPort("point_cloud_W", Value(PointCloud()))
        self.DeclareAbstractOutputPort(
            "object_cloud", lambda: Value(ObjectCloud.empty()),
            self._calc, prerequisites_of_calc={self.all_input_ports_ticket()},
        )

    @stage("rendering")
    def _calc(self, context, output) -> None:
        cloud = self._cloud_port.Eval(context)
        output.set_value(extract_object_cloud(cloud.xyzs().T, lower=self._lower, upper=self._upper,
                                              config=self._config, cameras=self._cameras))


class PointCloudFusion(LeafSystem):
    """`count` world-frame PointClouds in (cloud_0, cloud_1, ...), their points as one PointCloud out."""

    def __init__(self, count: int):
        super().__init__()
        self._ports = [self.DeclareAbstractInputPort(f"cloud_{k}", Value(PointCloud())) for k in range(count)]
        self.DeclareAbstractOutputPort("point_cloud_W", lambda: Value(PointCloud()), self._calc,
                                       prerequisites_of_calc={self.all_input_ports_ticket()})

    def _calc(self, context, output) -> None:
        xyzs = np.concatenate([port.Eval(context).xyzs() for port in self._ports], axis=1)
        cloud = PointCloud(xyzs.shape[1])
        cloud.mutable_xyzs()[:] = xyzs
        output.set_value(cloud)
