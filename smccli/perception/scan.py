"""A planar lidar scan as a simple localized perception (SL, eq. 11-12; paper 4.2).

The value of the perception is the room's outline as the lidar sees it; its location is
the lidar's pose, from odometry, when the scan was taken. Three things are built on it:

* :func:`align_scans` -- the SE(2) transform between two scans of one room, by ICP from
  12 yaw seeds (ICP alone converges from about 30 deg / 0.5 m only, docs/design.md section 9);
* :func:`scan_distance` -- d_P of two scans (eq. 12), 0 for the same place, >= 1 for
  clearly different places: a trimmed chamfer distance after alignment, over a scale;
* the transform that carries a base goal stored with the demo scan over to the current
  scan (eq. 38-39, :mod:`smccli.learn.frames`), so that odometry's drift cancels.

Poses are (x, y, theta) arrays [m, m, rad]; transforms are 3x3 homogeneous SE(2)
matrices, ``T_a_b`` mapping points of frame b into frame a (:mod:`smccli.world.geometry`).
"""

from __future__ import annotations

import os
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from smccli.world.geometry import se2, se2_pose, se2_se3

_REG = o3d.pipelines.registration
_MIN_POINTS = 10
"""Fewer valid beams than this make no outline to align [points]."""
_V = TypeVar("_V")


class Memo(Generic[_V]):
    """The last ``kept`` values made, by key, least recently used first out. For values
    that are pure functions of their key and never changed by their users; safe across a
    Dask worker's threads (the value is made outside the lock: two threads may both make
    it, and get equal values)."""

    def __init__(self, kept: int) -> None:
        self.kept = kept
        self._values: OrderedDict[Hashable, _V] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: Hashable, make: Callable[[], _V]) -> _V:
        """The value of ``key``, made by ``make()`` unless kept."""
        with self._lock:
            if key in self._values:
                self._values.move_to_end(key)
                return self._values[key]
        value = make()
        with self._lock:
            self._values[key] = value
            while len(self._values) > self.kept:
                self._values.popitem(last=False)
        return value


_TARGETS: Memo[o3d.geometry.PointCloud] = Memo(64)
"""The last target clouds with their normals, by points and neighbour count: a decision
aligns the scan it sees to each stored scan of the tree, the same ones every time, and
their normals cost as much as a third of the ICP."""
_OUTLINES: Memo[tuple[np.ndarray, cKDTree]] = Memo(64)
"""The last target scans' beam end points and the k-d tree of their outline, by
:func:`scan_key` and the outline's parameters: a decision's chamfer measures against the
tree's stored scans, the same ones every time (the outline and its tree: 0.4 of 1 ms)."""


# --- the scan ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Scan2D:
    """A planar lidar scan: beam i has bearing ``angle_min + i * angle_increment``."""

    ranges: np.ndarray
    """Ranges, shape (n,) [m]; inf, nan, <= 0 (MuJoCo's "no hit" is -1) or >= ``range_max``
    mean no return."""
    angle_min: float
    """Bearing of the first beam in the sensor frame [rad], counter-clockwise about z."""
    angle_increment: float
    """Bearing step between beams [rad], > 0."""
    range_max: float
    """Readings at or beyond this are no return [m]."""

    def __post_init__(self) -> None:
        r = np.asarray(self.ranges, dtype=np.float64)
        if r.ndim != 1:
            raise ValueError(f"Scan2D: ranges must have shape (n,), got {r.shape}")
        if not self.angle_increment > 0:
            raise ValueError(f"Scan2D: angle_increment must be > 0, got {self.angle_increment}")
        if not self.range_max > 0:
            raise ValueError(f"Scan2D: range_max must be > 0, got {self.range_max}")
        object.__setattr__(self, "ranges", r)

    @classmethod
    def from_span(
        cls, ranges: np.ndarray, start_angle: float, end_angle: float, range_max: float
    ) -> Scan2D:
        """From a ``foxglove.LaserScan``'s first and last bearing (beams evenly spaced,
        both ends included) [rad]."""
        n = len(ranges)
        step = (end_angle - start_angle) / (n - 1) if n > 1 else 2 * np.pi
        return cls(np.asarray(ranges), float(start_angle), float(step), float(range_max))

    def angles(self) -> np.ndarray:
        """Bearings of the beams, shape (n,) [rad]."""
        return self.angle_min + self.angle_increment * np.arange(len(self.ranges))

    def valid(self) -> np.ndarray:
        """Which beams returned, shape (n,) bool."""
        r = self.ranges
        with np.errstate(invalid="ignore"):
            return np.isfinite(r) & (r > 0) & (r < self.range_max)

    def points(self) -> np.ndarray:
        """End points of the beams that returned, shape (k, 2) [m], sensor frame."""
        ok = self.valid()
        a, r = self.angles()[ok], self.ranges[ok]
        return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def scan_key(s: Scan2D) -> tuple[bytes, float, float, float]:
    """A hashable key equal for scans with the same readings and beams (caches)."""
    return (s.ranges.tobytes(), s.angle_min, s.angle_increment, s.range_max)


def scan_to_dict(s: Scan2D) -> dict:
    """JSON-ready form of a scan (no return -> None), for tree files and logs."""
    ok = s.valid()
    return {
        "ranges": [float(r) if v else None for r, v in zip(s.ranges, ok, strict=True)],
        "angle_min": float(s.angle_min),
        "angle_increment": float(s.angle_increment),
        "range_max": float(s.range_max),
    }


def scan_from_dict(d: dict) -> Scan2D:
    """Inverse of :func:`scan_to_dict`."""
    ranges = np.array([np.inf if r is None else r for r in d["ranges"]], dtype=np.float64)
    return Scan2D(ranges, float(d["angle_min"]), float(d["angle_increment"]), float(d["range_max"]))


# --- parameters ----------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ScanParams:
    """Knobs of :func:`align_scans` and :func:`scan_distance`."""

    n_seeds: int = 12
    """Yaw seeds, evenly spaced over 2 pi, each with the centroids aligned: ICP from a
    single guess converges from about 30 deg / 0.5 m only (docs/design.md section 9)."""
    coarse_distances: tuple[float, ...] = (1.0, 0.3)
    """Correspondence distances of the ICP stages run from every seed [m]: wide first, to
    pull in a seed that is off by a sector, then narrower."""
    fine_distance: float = 0.1
    """Correspondence distance of the last ICP stage, run from the best seed only [m]."""
    max_iterations: int = 30
    """ICP iterations per stage."""
    point_to_plane: bool = True
    """Point-to-plane ICP with in-plane normals of the target (median 1.1 mm / 0.03 deg on
    the synthetic rooms of the tests, 1.5 mm / 0.03 deg in MuJoCo); False: point-to-point
    (2.5 mm / 0.06 deg, biased by the beams hitting a wall at other places in each scan)."""
    normal_neighbours: int = 6
    """Points in the PCA of a 2-D normal (the point itself included): about +-3 beams."""
    inlier_distance: float = 0.05
    """A source point with a target point within this is an inlier: fitness and RMSE [m]."""
    fitness_tie: float = 0.02
    """Seeds whose fitness is within this of the best tie; the lowest RMSE among them wins
    (range noise moves the fitness of equally good seeds by about 1 %)."""
    keep: float = 0.85
    """Share of the nearest-neighbour distances kept, each way, by the trimmed chamfer:
    the rest is what one pose sees and the other does not (behind furniture, through a
    door), which says nothing about the place."""
    polyline_step: float = 0.01
    """Spacing of the points that densify the scan's outline for the chamfer [m]."""
    max_incidence: float = 1.4
    """Consecutive beams are joined into the outline when their ranges differ by less than
    a wall at this incidence would make them (80 deg: 10 % of the range for 1 deg beams)
    plus ``join_slack`` [rad]; larger jumps are an edge (furniture before a wall)."""
    join_slack: float = 0.05
    """Absolute range difference always joined (range noise) [m]."""
    distance_scale: float = 0.3
    """Trimmed chamfer distance that counts as "clearly different" (-> d_P = 1) [m].

    T_hP = 0.1 then sits at 3 cm. Measured: the same room from poses up to 0.5 m and any
    yaw apart gives <= 2.6 cm in MuJoCo (point chamfer, docs/design.md) and <= 0.9 cm on the
    synthetic rooms of the tests (outline chamfer, 1 cm range noise; 0.2 cm without);
    another room of a different shape 7-12 cm in MuJoCo (d_P 0.23-0.4) and 16-47 cm in the
    tests (0.52-1.58).
    """


# --- alignment -----------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ScanAlignment:
    """Where a source scan sits in a target scan's frame (the result of :func:`align_scans`)."""

    T_target_source: np.ndarray
    """SE(2) transform, shape (3, 3): source sensor frame -> target sensor frame, i.e. the
    source lidar's pose in the target lidar's frame."""
    fitness: float
    """Share of the source points with a target point within ``inlier_distance``, in [0, 1]."""
    rmse: float
    """RMS distance of those inliers to their nearest target point [m]."""

    @property
    def pose(self) -> np.ndarray:
        """The transform as (x, y, yaw) [m, m, rad], yaw in (-pi, pi]."""
        return se2_pose(self.T_target_source)


def _normals_2d(xy: np.ndarray, k: int) -> np.ndarray:
    """Unit in-plane normals of points (n, 2), shape (n, 2): the least principal axis of
    each point's k nearest neighbours. The sign is arbitrary (point-to-plane ignores it)."""
    k = min(k, len(xy))
    _, idx = cKDTree(xy).query(xy, k)
    nb = xy[idx] - xy[idx].mean(axis=1, keepdims=True)
    _, vecs = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))
    return vecs[:, :, 0]


def _cloud(xy: np.ndarray, normals: np.ndarray | None = None) -> o3d.geometry.PointCloud:
    """Points (n, 2) on the z = 0 plane; normals (n, 2) with n_z = 0 make point-to-plane
    residuals in-plane, so ICP cannot trade x-y error for roll, pitch or z."""
    zeros = np.zeros((len(xy), 1))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.hstack([xy, zeros])))
    if normals is not None:
        cloud.normals = o3d.utility.Vector3dVector(np.hstack([normals, zeros]))
    return cloud


def _target_cloud(xy: np.ndarray, k: int) -> o3d.geometry.PointCloud:
    """:func:`_cloud` of target points (n, 2) with their normals, from :data:`_TARGETS` when
    the same points came before (ICP reads the target, never changes it)."""
    return _TARGETS.get((xy.tobytes(), k), lambda: _cloud(xy, _normals_2d(xy, k)))


_POOL: tuple[int, ThreadPoolExecutor] | None = None
"""This process's threads for the seeds of :func:`align_scans` (its pid: a forked campaign
worker makes its own)."""


def _map_seeds(
    refine: Callable[[np.ndarray], tuple[np.ndarray, float, float]], seeds: list[np.ndarray]
) -> list[tuple[np.ndarray, float, float]]:
    """``refine`` of each seed, in order: on two threads when there are several seeds and
    cores. open3d's ICP lets go of the GIL and each call runs on one thread of its own
    (``o3d.utility.set_max_threads(1)``), so the results are a single thread's to the bit;
    a room's decision aligns a scan per SMC, 12 seeds each, which was most of its time."""
    global _POOL
    if len(seeds) < 2 or (os.cpu_count() or 1) < 2:
        return [refine(T) for T in seeds]
    if _POOL is None or _POOL[0] != os.getpid():
        _POOL = (os.getpid(), ThreadPoolExecutor(2, thread_name_prefix="smc-icp"))
    return list(_POOL[1].map(refine, seeds))


def _checked_points(scan: Scan2D, role: str) -> np.ndarray:
    xy = scan.points()
    if len(xy) < _MIN_POINTS:
        raise ValueError(
            f"align_scans: {role} scan has {len(xy)} beams with a return, need >= {_MIN_POINTS}"
        )
    return xy


def align_scans(
    target: Scan2D,
    source: Scan2D,
    params: ScanParams | None = None,
    *,
    initial: np.ndarray | None = None,
    search: bool = True,
) -> ScanAlignment:
    """SE(2) transform mapping ``source`` points into ``target``'s frame, by multi-seed ICP.

    Each of ``n_seeds`` yaws, with the translation that aligns the centroids, is refined
    by ICP with the ``coarse_distances`` stages; the seed with the best fitness (ties
    within ``fitness_tie`` broken by RMSE) gets a last stage at ``fine_distance``.
    ``initial`` (3, 3), when given (e.g. from odometry), is tried as one more seed; with
    ``search=False`` it is the only one (tracking a scan already aligned: about 3 ms
    instead of 40-90 ms).
    Every stage's result is projected onto SE(2). A room with a rotational symmetry (an
    empty rectangle) has as many equally good answers; furniture breaks the tie.
    """
    params = params or ScanParams()
    xy_t = _checked_points(target, "target")
    xy_s = _checked_points(source, "source")
    tgt = _target_cloud(xy_t, params.normal_neighbours)
    src = _cloud(xy_s)
    est = (
        _REG.TransformationEstimationPointToPlane()
        if params.point_to_plane
        else _REG.TransformationEstimationPointToPoint()
    )
    criteria = _REG.ICPConvergenceCriteria(max_iteration=params.max_iterations)

    def icp(T: np.ndarray, distance: float) -> np.ndarray:
        r = _REG.registration_icp(src, tgt, distance, se2_se3(T), est, criteria)
        return se2(se2_pose(r.transformation))  # the nearest SE(2): yaw of the x-y block

    def score(T: np.ndarray) -> tuple[float, float]:
        e = _REG.evaluate_registration(src, tgt, params.inlier_distance, se2_se3(T))
        return float(e.fitness), float(e.inlier_rmse)

    c_t, c_s = xy_t.mean(axis=0), xy_s.mean(axis=0)
    seeds = []
    for yaw in (
        2
        * np.pi
        * np.arange(params.n_seeds if search or initial is None else 0)
        / max(params.n_seeds, 1)
    ):
        T = se2((0.0, 0.0, yaw))
        T[:2, 2] = c_t - T[:2, :2] @ c_s
        seeds.append(T)
    if initial is not None:
        seeds.append(np.asarray(initial, dtype=np.float64))

    def refine(T: np.ndarray) -> tuple[np.ndarray, float, float]:
        for d in params.coarse_distances:
            T = icp(T, d)
        # A lone seed (tracking) wins unscored: one of its two evaluations saved.
        return (T, *score(T)) if len(seeds) > 1 else (T, 0.0, 0.0)

    results = _map_seeds(refine, seeds)
    best_fit = max(f for _, f, _ in results)
    T, _, _ = min((r for r in results if r[1] >= best_fit - params.fitness_tie), key=lambda r: r[2])
    T = icp(T, params.fine_distance)
    fitness, rmse = score(T)
    return ScanAlignment(T_target_source=T, fitness=fitness, rmse=rmse)


# --- distance (eq. 12) ---------------------------------------------------------------------


def outline(scan: Scan2D, params: ScanParams | None = None) -> np.ndarray:
    """The scan's outline as dense points, shape (m, 2) [m], sensor frame: the beam end
    points plus points every ``polyline_step`` along the segments joining consecutive beams
    on one surface (see ``max_incidence``).

    The chamfer then measures the distance to the surface, not to the nearest beam: beams
    1 deg apart are 7 cm apart on a wall 4 m away, which a point chamfer would count as
    up to 3.5 cm of mismatch between two scans of the same wall.
    """
    params = params or ScanParams()
    ok = scan.valid()
    a, r = scan.angles(), np.where(ok, scan.ranges, 0.0)
    xy = np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
    n = len(r)
    full_circle = n * scan.angle_increment >= 2 * np.pi - 1e-6
    i = np.arange(n if full_circle else n - 1)
    j = (i + 1) % n
    tol = np.tan(params.max_incidence) * scan.angle_increment
    joined = (
        ok[i] & ok[j] & (np.abs(r[i] - r[j]) <= tol * np.minimum(r[i], r[j]) + params.join_slack)
    )
    i, j = i[joined], j[joined]
    n_sub = np.ceil(np.linalg.norm(xy[j] - xy[i], axis=1) / params.polyline_step).astype(int)
    # Segment s gets interior points at the fractions k / n_sub[s], k = 1 .. n_sub[s] - 1.
    n_in = np.maximum(n_sub - 1, 0)
    seg = np.repeat(np.arange(len(i)), n_in)
    k = np.arange(len(seg)) - np.repeat(np.cumsum(n_in) - n_in, n_in) + 1
    f = (k / np.maximum(n_sub[seg], 1))[:, None]
    return np.concatenate([xy[ok], xy[i[seg]] + f * (xy[j[seg]] - xy[i[seg]])])


def _trimmed_mean(d: np.ndarray, keep: float) -> float:
    d = np.sort(d)
    return float(d[: max(1, int(np.ceil(keep * len(d))))].mean())


def chamfer(
    target: Scan2D, source: Scan2D, T_target_source: np.ndarray, params: ScanParams | None = None
) -> float:
    """Trimmed symmetric chamfer distance of two scans once ``source`` is moved into
    ``target``'s frame by ``T_target_source`` (3, 3) [m].

    The mean of the two ways' trimmed means (the nearest ``keep`` share) of the distances
    from each scan's beam end points to the other scan's :func:`outline`.
    """
    params = params or ScanParams()
    R, t = T_target_source[:2, :2], T_target_source[:2, 2]
    pts_t, tree_t = _target_outline(target, params)
    pts_s = source.points() @ R.T + t
    line_s = outline(source, params) @ R.T + t
    d_st = tree_t.query(pts_s)[0]
    d_ts = cKDTree(line_s).query(pts_t)[0]
    return 0.5 * (_trimmed_mean(d_st, params.keep) + _trimmed_mean(d_ts, params.keep))


def _target_outline(target: Scan2D, params: ScanParams) -> tuple[np.ndarray, cKDTree]:
    """The beam end points (k, 2) of ``target`` and the k-d tree of its :func:`outline`,
    from :data:`_OUTLINES` when the same scan came before (neither is ever changed)."""
    key = (scan_key(target), params.polyline_step, params.max_incidence, params.join_slack)

    def make() -> tuple[np.ndarray, cKDTree]:
        pts = target.points()
        pts.setflags(write=False)
        return pts, cKDTree(outline(target, params))

    return _OUTLINES.get(key, make)


def scan_distance(a: Scan2D, b: Scan2D, params: ScanParams | None = None) -> float:
    """d_P of two scans (eq. 12): ~0 for the same place, >= 1 for clearly different ones.

    :func:`chamfer` after :func:`align_scans` (``b`` onto ``a``), over ``distance_scale``
    (0.3 m: T_hP = 0.1 at 3 cm; the same room <= 2.6 cm, other rooms >= 7 cm, measured).
    The pose plays no part: it is the location, compared by d_X (eq. 13).

    Known limitation: a scan sees geometry only. Rooms congruent under a rotation and
    translation, e.g. the mirror image of a room whose own layout is mirror-symmetric
    (1.0 cm in MuJoCo, docs/design.md section 9), score as the same place; the mirror image of
    a room with a lopsided layout scored 5.5-6 cm (0.18-0.20) in the tests: apart, but by
    far less than a room of another shape (>= 0.52). Give each room its own size and
    furniture, or let the room histogram (SI) tell them apart.
    """
    params = params or ScanParams()
    al = align_scans(a, b, params)
    return chamfer(a, b, al.T_target_source, params) / params.distance_scale


# --- goal mapping (eq. 38-39) --------------------------------------------------------------
