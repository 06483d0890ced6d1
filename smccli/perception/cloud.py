"""Depth image -> coloured world-frame points -> crop -> table removal -> self-filter."""

from __future__ import annotations

import itertools
import threading
from collections.abc import Sequence

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from smccli.perception.moments import moments
from smccli.perception.params import PerceptionParams
from smccli.world.sensors import CameraFrame, RobotGeometry


def _rays(K: np.ndarray, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Normalised image coordinates ``(x_n, y_n)`` of every pixel of an ``h`` x ``w``
    image with intrinsics ``K``, each (h * w,) float64 in row-major order: the pinhole
    back-projection's per-pixel part, computed once per camera (the skew ``K[0, 1]`` kept
    for generality)."""
    key = (K.tobytes(), h, w)
    rays = _RAYS.get(key)
    if rays is None:
        v, u = np.divmod(np.arange(h * w), w)
        y_n = (v - K[1, 2]) / K[1, 1]
        x_n = (u - K[0, 2] - K[0, 1] * y_n) / K[0, 0]
        if len(_RAYS) >= 8:  # a few cameras per process; never grows without bound
            _RAYS.clear()
        rays = _RAYS[key] = (x_n, y_n)
    return rays


_RAYS: dict[tuple[bytes, int, int], tuple[np.ndarray, np.ndarray]] = {}


def points_from_depth(
    frame: CameraFrame,
    max_depth: float = 5.0,
    region: tuple[int, int, int, int] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Lift every valid depth pixel into the world frame.

    Returns points, shape (n, 3) [m] in the world frame, and their colours, shape (n, 3)
    uint8 RGB, in the image's row-major order. Invalid pixels (0, inf, nan, beyond
    ``max_depth``) are dropped; with ``region`` ``(v0, v1, u0, u1)`` so are the pixels
    outside rows ``v0:v1`` and columns ``u0:u1`` (:func:`crop_region`).
    """
    points, pixels = _lift(frame, max_depth, region)
    return points, pixel_colours(frame, pixels)


def pixel_colours(frame: CameraFrame, pixels: np.ndarray) -> np.ndarray:
    """The colours (n, 3) uint8 of ``frame``'s pixels at row-major indices ``pixels`` (n,)."""
    return np.take(np.asarray(frame.rgb).reshape(-1, 3), pixels, axis=0)


def _lift(
    frame: CameraFrame,
    max_depth: float,
    region: tuple[int, int, int, int] | None,
    box: tuple[tuple[float, ...], tuple[float, ...]] | None = None,
    base: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`points_from_depth` with each point's row-major pixel index (n,) int64 in
    place of its colour: the depth alone is read, and the colours of the points kept at
    the end are gathered then (:func:`pixel_colours`; a frame's colours may still be
    drawing, :class:`~smccli.world.sensors.DrawingFrame`). With ``box`` (lo, hi), each
    (3,) [m] in the world frame (with ``base`` ``[x, y, yaw]``, the base's), only the
    points inside it (:func:`crop_mask`'s test, on the same values): the crop made on the
    coordinates' columns before they are interleaved."""
    depth = np.asarray(frame.depth, dtype=np.float32)
    h, w = depth.shape
    K = np.asarray(frame.K, dtype=np.float64)
    if region is None:
        valid = np.isfinite(depth) & (depth > 0) & (depth < max_depth)
    else:
        v0, v1, u0, u1 = region
        sub = depth[v0:v1, u0:u1]
        valid = np.zeros((h, w), dtype=bool)
        valid[v0:v1, u0:u1] = np.isfinite(sub) & (sub > 0) & (sub < max_depth)
    idx = np.flatnonzero(valid)
    n = len(idx)
    x_n, y_n = _rays(K, h, w)
    # Vectors written in place: fresh (n,) and (n, 3) arrays (1.8 MB for 320 x 240) cost
    # more than the arithmetic on this machine, in page faults.
    z, x, y, term = _scratch("lift", (4, n))
    world = _scratch("lift_world", (3, n))
    # Pinhole back-projection in the optical frame (x right, y down, z forward); the same
    # products as gathering first, without the gathers where every pixel is valid.
    every = n == h * w
    if every:
        z[:] = depth.reshape(-1)
        np.multiply(x_n, z, out=x)
        np.multiply(y_n, z, out=y)
    else:
        z[:] = np.take(depth.reshape(-1), idx)
        np.multiply(np.take(x_n, idx), z, out=x)
        np.multiply(np.take(y_n, idx), z, out=y)
    T = np.asarray(frame.T_world_camera, dtype=np.float64)
    # R p + t column by column, each row's three products summed as
    # ``np.einsum("ij,nj->ni", R, p)`` sums them, (x R_i0 + z R_i2) + y R_i1 (its SIMD
    # lanes), which the points trees were compiled from were lifted with: equal to the bit
    # on 7.5 M points of 101 campaign frames and 600 k random ones; 1.65 to 0.6 ms a lift.
    # (Not ``p @ R.T``: a threaded BLAS call is ten times slower on a busy machine.)
    for i in range(3):
        acc = world[i]
        np.multiply(x, T[i, 0], out=acc)
        np.multiply(z, T[i, 2], out=term)
        acc += term
        np.multiply(y, T[i, 1], out=term)
        acc += term
        acc += T[i, 3]
    if box is None:
        return np.ascontiguousarray(world.T), idx
    lo, hi = box
    # The kept columns gathered by their indices, found once: three ``np.compress`` each
    # found them again (0.3 to 0.2 ms for 67 k points).
    kept = np.flatnonzero(_in_box(world if base is None else _base_columns(world, base), lo, hi))
    points = np.empty((len(kept), 3))
    for i in range(3):
        points[:, i] = world[i].take(kept)
    return points, kept if every else idx.take(kept)


_SCRATCH = threading.local()


def _scratch(name: str, shape: tuple[int, ...]) -> np.ndarray:
    """A C-contiguous float64 array of ``shape``, this thread's scratch for ``name``'s use
    reused call after call (overwritten by the next)."""
    size = int(np.prod(shape))
    buf = getattr(_SCRATCH, name, None)
    if buf is None or len(buf) < size:
        buf = np.empty(size)
        setattr(_SCRATCH, name, buf)
    return buf[:size].reshape(shape)


def crop_region(
    frame: CameraFrame, params: PerceptionParams, base: np.ndarray | None = None
) -> tuple[int, int, int, int] | None:
    """The image rows and columns ``(v0, v1, u0, u1)`` outside which no pixel of ``frame``
    lifts into the crop box (:func:`crop_mask`), or None for the whole image: the
    :func:`view_region` of the box, its near bound the frame's nearest reading."""
    depth = np.asarray(frame.depth, dtype=np.float32)
    # The least reading in place, not of a copy of the readings (0.1 to 0.05 ms).
    near = float(np.min(depth, where=np.isfinite(depth) & (depth > 0), initial=np.inf))
    if near == np.inf:
        return None
    return view_region(
        np.asarray(frame.K, float),
        np.asarray(frame.T_world_camera, float),
        depth.shape[:2],
        near,
        params,
        base,
    )


def view_region(
    K: np.ndarray,
    T_world_camera: np.ndarray,
    shape: tuple[int, int],
    near: float,
    params: PerceptionParams,
    base: np.ndarray | None = None,
) -> tuple[int, int, int, int] | None:
    """The rows and columns ``(v0, v1, u0, u1)`` of an image of ``shape`` (h, w) from a
    camera with intrinsics ``K`` (3, 3) [px] at ``T_world_camera`` (4, 4, optical frame)
    outside which no depth reading between ``near`` and ``params.max_depth`` [m] lifts
    into the crop box; None for the whole image, ``(0, 0, 0, 0)`` when none can.

    Such a point lies in a convex polytope (the box cut by that depth slab) whose image,
    all of it in front of the camera, is the convex hull of its vertices' images. Their
    bounding rectangle, widened by two pixels for rounding, holds every pixel whose point
    is in the box.
    """
    h, w = shape
    far = params.max_depth
    lo, hi = params.crop_min, params.crop_max
    corners = np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )
    if params.crop_frame == "base":
        if base is None:
            raise ValueError("perception.crop_frame=base needs the base's pose")
        c, s = np.cos(base[2]), np.sin(base[2])
        bx, by = corners[:, 0].copy(), corners[:, 1].copy()
        corners[:, 0] = base[0] + c * bx - s * by
        corners[:, 1] = base[1] + s * bx + c * by
    T = T_world_camera
    p = np.einsum("ji,nj->ni", T[:3, :3], corners - T[:3, 3])  # R^T (x - t)
    # The cut polytope's vertices: the corners inside the slab, and where the box's edges
    # (corners differing in one coordinate: one bit of their index) cross its two faces.
    verts = [p[(p[:, 2] >= near) & (p[:, 2] <= far)]]
    for a in range(8):
        for bit in (1, 2, 4):
            b = a | bit
            if b == a:
                continue
            za, zb = p[a, 2], p[b, 2]
            for level in (near, far):
                if (za - level) * (zb - level) < 0:
                    verts.append((p[a] + (level - za) / (zb - za) * (p[b] - p[a]))[None])
    q = np.concatenate(verts)
    if not len(q):
        return (0, 0, 0, 0)  # the box is out of sight
    x_n, y_n = q[:, 0] / q[:, 2], q[:, 1] / q[:, 2]
    u = K[0, 0] * x_n + K[0, 1] * y_n + K[0, 2]
    v = K[1, 1] * y_n + K[1, 2]
    v0, v1 = min(max(int(np.floor(v.min())) - 2, 0), h), min(max(int(np.ceil(v.max())) + 3, 0), h)
    u0, u1 = min(max(int(np.floor(u.min())) - 2, 0), w), min(max(int(np.ceil(u.max())) + 3, 0), w)
    if (v0, v1, u0, u1) == (0, h, 0, w):
        return None
    return (v0, max(v1, v0), u0, max(u1, u0))


def in_crop_frame(
    points: np.ndarray, params: PerceptionParams, base: np.ndarray | None = None
) -> np.ndarray:
    """``points`` (n, 3) in the crop box's frame: the world's, or with ``params.crop_frame
    == "base"`` that of the base at ``base`` ``[x, y, yaw]`` (odometry's frame, as the
    points)."""
    if params.crop_frame != "base":
        return points
    return np.column_stack(_base_columns(points.T, base))


def _base_columns(columns: np.ndarray, base: np.ndarray | None) -> list[np.ndarray]:
    """The coordinates' columns (3, n) [m] of points in odometry's frame, in the frame of
    the base at ``base`` ``[x, y, yaw]``: three columns (n,)."""
    if base is None:
        raise ValueError("perception.crop_frame=base needs the base's pose")
    c, s = np.cos(base[2]), np.sin(base[2])
    dx, dy = columns[0] - base[0], columns[1] - base[1]
    return [c * dx + s * dy, -s * dx + c * dy, columns[2]]


def crop_mask(
    points: np.ndarray, params: PerceptionParams, base: np.ndarray | None = None
) -> np.ndarray:
    """Points inside the axis-aligned workspace box, boolean mask of shape (n,); the box
    is in the frame :func:`in_crop_frame` says."""
    lo, hi = params.crop_min, params.crop_max
    points = in_crop_frame(points, params, base)
    return _in_box(points.T, lo, hi)


def _in_box(
    columns: np.ndarray | Sequence[np.ndarray], lo: Sequence[float], hi: Sequence[float]
) -> np.ndarray:
    """Points inside the box ``lo``..``hi`` (3,) [m], bounds included, boolean mask (n,) of
    the points given as their coordinates' columns (3, n) (``points.T`` is a view)."""
    # Column by column: the (n, 3) comparisons and their ``all`` took 8 times as long.
    keep = (columns[0] >= lo[0]) & (columns[0] <= hi[0])
    for k in (1, 2):
        keep &= (columns[k] >= lo[k]) & (columns[k] <= hi[k])
    return keep


def self_filter_mask(points: np.ndarray, robot: RobotGeometry | None) -> np.ndarray:
    """Points outside every bounding sphere of the robot, boolean mask of shape (n,): a
    point is out of a sphere when its squared distance to the centre exceeds the squared
    radius."""
    keep = np.ones(len(points), dtype=bool)
    if robot is None or len(robot.radii) == 0 or len(points) == 0:
        return keep
    centers = np.asarray(robot.centers, dtype=np.float64)
    radii = np.asarray(robot.radii, dtype=np.float64)
    # A k-d tree names the few (point, sphere) pairs that can be inside (the radius a hair
    # wider than the test's): a test of every point against each of the ~50 spheres took
    # 5 ms a decision. The test itself is the same arithmetic on those pairs. The tree
    # holds only the points in the spheres' bounding box (about half of a decision's), and
    # unbalanced it builds in half the time; any tree names every pair the test keeps:
    # 2.1 to 0.9 ms a decision. Leaves of 128 points, searched point by point, cost less
    # than the descent to leaves of 16: 0.85 to 0.73 ms (weigh_sort's 1.36 to 1.13 ms).
    reach = radii * (1 + 1e-9) + 1e-12
    lo, hi = (centers - reach[:, None]).min(axis=0), (centers + reach[:, None]).max(axis=0)
    candidates = np.flatnonzero(_in_box(points.T, lo, hi))
    if not len(candidates):
        return keep
    tree = cKDTree(points[candidates], leafsize=128, balanced_tree=False, compact_nodes=False)
    near = tree.query_ball_point(centers, reach, return_sorted=False)
    counts = [len(n) for n in near]
    total = sum(counts)
    if not total:
        return keep
    sphere = np.repeat(np.arange(len(radii)), counts)
    point = candidates[np.fromiter(itertools.chain.from_iterable(near), np.int64, total)]
    d = points[point] - centers[sphere]
    inside = ~(np.einsum("ij,ij->i", d, d) > radii[sphere] * radii[sphere])
    keep[point[inside]] = False
    return keep


def _ransac_plane(points: np.ndarray, params: PerceptionParams) -> tuple[np.ndarray, int]:
    """The biggest plane ``[a, b, c, d]`` (unit normal) by RANSAC (open3d ``segment_plane``)
    and its inlier count in the subsample."""
    # RANSAC cost grows with the points scored per iteration; a strided subsample finds
    # the same plane (the table is most of the cloud) and the refinement uses all points.
    stride = max(1, len(points) // params.plane_sample)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points[::stride]))
    # open3d's RANSAC draws random samples; seeding makes the same frame give the same
    # plane (a least-squares refinement removes the remaining sampling jitter).
    o3d.utility.random.seed(params.plane_seed)
    plane, inliers = pcd.segment_plane(
        distance_threshold=params.plane_distance,
        ransac_n=3,
        num_iterations=params.plane_iterations,
    )
    plane = np.asarray(plane, dtype=np.float64)
    return plane / np.linalg.norm(plane[:3]), len(inliers)


def fit_table_plane(
    points: np.ndarray, params: PerceptionParams, start: np.ndarray | None = None
) -> np.ndarray | None:
    """Fit the table plane with RANSAC (open3d ``segment_plane``), refined by least squares.

    Returns ``[a, b, c, d]`` with ``a x + b y + c z + d = 0``, unit normal pointing up
    (+z), or None if no near-horizontal plane with enough support is found. ``start``: the
    table plane of an earlier frame from the same camera pose; when at least half the
    points lie on it and the refinement from it reaches a fixed point, that is the plane,
    without RANSAC (the refinement reaches the same fixed point from RANSAC's hypothesis:
    bit-identical on every frame of the sample trees and campaigns).
    """
    return _table_plane(points, params, start)[0]


def _table_plane(
    points: np.ndarray, params: PerceptionParams, start: np.ndarray | None
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """:func:`fit_table_plane` and the points' :func:`plane_distance` (n,) [m] to it (None
    without a plane): the caller splits table from objects by them, a pass over the
    cloud (~0.3 ms) not made again."""
    if len(points) < 3:
        return None, None
    if start is not None:
        # Not kept: holding these 0.5 MB through the refinement made it 1.6 ms slower
        # (its own arrays no longer fit in the freed memory: fresh pages).
        mask = np.abs(plane_distance(points, start)) < params.plane_distance
        if 2 * np.count_nonzero(mask) >= len(points):
            plane, fixed, dist = _refine_plane(points, mask, params)
            if fixed:
                return plane, dist
    plane, n_inliers = _ransac_plane(points, params)
    if plane[2] < 0:
        plane = -plane
    if np.arccos(np.clip(plane[2], -1.0, 1.0)) > params.plane_max_tilt or n_inliers < 3:
        return None, None  # the biggest plane is a wall or an object face: no table in view
    mask = np.abs(plane_distance(points, plane)) < params.plane_distance
    plane, _, dist = _refine_plane(points, mask, params)
    return plane, dist


def _refine_plane(
    points: np.ndarray, mask: np.ndarray, params: PerceptionParams
) -> tuple[np.ndarray, bool, np.ndarray]:
    """Least-squares refinement of the plane through ``points[mask]`` (n, 3), iterated to a
    fixed point (at most 10 times): the plane, whether it was reached and the points'
    distances (n,) [m] to the plane.

    The plane through the inliers' mean, normal = direction of least variance. open3d's
    RANSAC runs on several threads and, on a busy machine, need not return the same
    hypothesis twice; the refined inlier set converges to the same set of table points
    from any nearby hypothesis, so the same frame always gives bit-identical planes (and
    trees).
    """
    for _ in range(10):
        # The inliers and their centred copy in scratch arrays: fresh 1.4 MB ones are fresh
        # pages, ~1 ms of a decision on this machine.
        k = int(np.count_nonzero(mask))
        inl, centered = _scratch("plane", (k, 3)), _scratch("plane_centered", (k, 4))
        np.compress(mask, points, axis=0, out=inl)
        mean, cov = moments(inl, centered)
        _, vecs = np.linalg.eigh(cov)
        normal = vecs[:, 0] if vecs[2, 0] > 0 else -vecs[:, 0]
        plane = np.r_[normal, -float(np.dot(normal, mean))]
        dist = plane_distance(points, plane)
        new_mask = np.abs(dist) < params.plane_distance
        if np.array_equal(new_mask, mask):
            return plane, True, dist
        mask = new_mask
    return plane, False, dist


_TABLES: dict[bytes, np.ndarray] = {}
"""The last table plane seen from each camera pose (T_world_camera's bytes): where the
next frame's refinement starts (:func:`fit_table_plane`)."""


def plane_distance(points: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """Signed distance of points (n, 3) to ``plane`` [a, b, c, d] (unit normal), shape (n,) [m]."""
    # Not ``points @ normal``: BLAS threads spin for ~20 ms on a busy 2-core machine for
    # what is a few microseconds of work, but ``np.einsum("ni,i->n", points, plane[:3])``,
    # which trees were compiled with. On float64 rows contiguous in memory (every cloud
    # here) it sums each row's products as (x a + z c) + y b (its SIMD lanes): so does this,
    # column by column, equal to the bit on 300 k random rows and every campaign frame
    # tried, 0.32 to 0.12 ms for a table's 67 k points. Other layouts sum in other orders.
    if points.dtype != np.float64 or points.strides[1] != points.itemsize:
        return np.einsum("ni,i->n", points, plane[:3]) + plane[3]
    out = points[:, 0] * plane[0]
    term = points[:, 2] * plane[2]
    out += term
    np.multiply(points[:, 1], plane[1], out=term)
    out += term
    out += plane[3]
    return out


def heights_above(points: np.ndarray, plane: np.ndarray | None) -> np.ndarray:
    """Height of points (n, 3) above the table plane, shape (n,) [m]; without a plane,
    above the lowest point."""
    return plane_distance(points, plane) if plane is not None else points[:, 2] - points[:, 2].min()


def above_plane_mask(points: np.ndarray, plane: np.ndarray, margin: float) -> np.ndarray:
    """Points more than ``margin`` [m] above the plane, boolean mask of shape (n,)."""
    return plane_distance(points, plane) > margin


def voxel_downsample(
    points: np.ndarray, colors: np.ndarray, voxel: float
) -> tuple[np.ndarray, np.ndarray]:
    """Keep the first point of each occupied voxel (deterministic, order-preserving), and
    its row of ``colors`` (colours, or pixel indices)."""
    if voxel <= 0 or len(points) == 0:
        return points, colors
    keys = np.floor(points / voxel).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    first.sort()
    return points[first], colors[first]


def remove_planes(
    points: np.ndarray, colors: np.ndarray, params: PerceptionParams
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Remove the big planes of any orientation (``params.remove_walls``): door panels,
    cabinet sides, shelves and tops, one RANSAC plane at a time while one holds at least
    ``wall_min_points`` points. Returns (points, colours (or whatever rows ``colors``
    holds: pixel indices), the near-horizontal planes, each
    ``[a, b, c, d]`` with its normal up): a cluster stands on the one just below it, if
    any (:func:`support_plane`)."""
    horizontal: list[np.ndarray] = []
    for _ in range(6):
        if len(points) < params.wall_min_points:
            break
        plane, _ = _ransac_plane(points, params)
        on = np.abs(plane_distance(points, plane)) < params.plane_distance
        if on.sum() < params.wall_min_points:
            break
        if plane[2] < 0:
            plane = -plane
        if np.arccos(np.clip(plane[2], -1.0, 1.0)) <= params.plane_max_tilt:
            horizontal.append(plane)
        points, colors = points[~on], colors[~on]
    return points, colors, horizontal


SUPPORT_GAP = 0.05
"""A cluster stands on a horizontal plane whose surface is at most this far below its
lowest point [m] (a can on a shelf, not a handle under a cabinet's top). Its sides may be
out of sight (a lying screwdriver seen from above showed only its top face, 3.7 cm over
the shelf)."""


def support_plane(points: np.ndarray, planes: list[np.ndarray]) -> np.ndarray | None:
    """Of ``planes`` (near-horizontal, normals up), the one ``points`` (n, 3) stand on:
    the highest whose surface lies at most SUPPORT_GAP below their lowest point; None."""
    best: tuple[float, np.ndarray] | None = None
    for plane in planes:
        low = float(plane_distance(points, plane).min())
        if -SUPPORT_GAP / 3 <= low <= SUPPORT_GAP and (best is None or low < best[0]):
            best = (low, plane)
    return None if best is None else best[1]


def object_points(
    frame: CameraFrame,
    robot: RobotGeometry | None,
    params: PerceptionParams,
    base: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The points standing on the table: lift, crop, downsample, remove the table, self-filter.

    Returns (points (n, 3) [m], colours (n, 3) uint8, table plane ``[a, b, c, d]`` or None).
    Without a table plane every cropped point is kept. ``base``: a mobile manipulator's
    base pose ``[x, y, yaw]`` when the crop box is in its frame; with ``remove_walls``
    every big plane goes and no single table is returned (:func:`object_points_on_planes`).
    """
    points, colors, planes, _ = object_points_on_planes(frame, robot, params, base)
    return points, colors, None if params.remove_walls else (planes[0] if planes else None)


def object_points_on_planes(
    frame: CameraFrame,
    robot: RobotGeometry | None,
    params: PerceptionParams,
    base: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """As :func:`object_points`, with every support plane found: the table's (at most
    one), or with ``remove_walls`` each near-horizontal plane removed; and the table's own
    points (m, 3) [m] and colours (m, 3) uint8, the reference of
    :mod:`smccli.perception.brightness` (none with ``remove_walls``: shelves differ; nor
    with ``brightness_scale`` 0, the brightness off: nothing reads them)."""
    points, pixels, planes, (table, table_pixels) = object_pixels_on_planes(
        frame, robot, params, base
    )
    return (
        points,
        pixel_colours(frame, pixels),
        planes,
        (table, pixel_colours(frame, table_pixels)),
    )


def object_pixels_on_planes(
    frame: CameraFrame,
    robot: RobotGeometry | None,
    params: PerceptionParams,
    base: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """:func:`object_points_on_planes` from the depth alone: each point's row-major pixel
    index (n,) int64 (the table's (m,)) in place of its colour (:func:`pixel_colours`)."""
    region = crop_region(frame, params, base)
    # The crop made in the lift: 0.5 ms less than on the lifted (n, 3) points (a mobile
    # manipulator's box in its base's frame: 1.9 to 1.0 ms).
    box = (params.crop_min, params.crop_max)
    on_base = params.crop_frame == "base"
    points, pixels = _lift(frame, params.max_depth, region, box, base if on_base else None)
    points, pixels = voxel_downsample(points, pixels, params.voxel_size)
    table = (np.zeros((0, 3)), np.zeros(0, dtype=np.int64))
    if params.remove_walls:
        points, pixels, planes = remove_planes(points, pixels, params)
    else:
        pose = np.asarray(frame.T_world_camera, dtype=np.float64).tobytes()
        plane, height = _table_plane(points, params, _TABLES.get(pose))
        if plane is not None:
            if len(_TABLES) >= 16:  # a few cameras at rest; one that moves never hits
                _TABLES.clear()
            _TABLES[pose] = plane
        planes = [] if plane is None else [plane]
        if plane is not None and height is not None:
            if params.brightness_scale > 0:  # the table is the brightness's reference alone
                table = _kept(np.abs(height) < params.plane_distance, points, pixels)
            # above_plane_mask, its distances reused
            points, pixels = _kept(height > params.plane_distance, points, pixels)
    if params.outlier_neighbours > 0 and len(points):
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        _, kept = pcd.remove_radius_outlier(
            nb_points=params.outlier_neighbours, radius=params.outlier_radius
        )
        idx = np.asarray(kept, dtype=int)
        points, pixels = points[idx], pixels[idx]
    # Self-filter last: the table is most of the cloud, so this tests far fewer points
    # against the robot's spheres; the robot's few points do not sway the RANSAC plane.
    points, pixels = _kept(self_filter_mask(points, robot), points, pixels)
    return points, pixels, planes, table


def _kept(mask: np.ndarray, points: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows of ``points`` (n, 3) and of ``rows`` (n, ...: colours, pixel indices)
    where ``mask`` (n,) holds: ``np.compress``, a quarter of boolean indexing's time on
    (n, 3) arrays."""
    return np.compress(mask, points, axis=0), np.compress(mask, rows, axis=0)


def cloud_from_frame(
    frame: CameraFrame,
    robot: RobotGeometry | None = None,
    params: PerceptionParams | None = None,
    *,
    crop: bool = True,
    base: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Coloured point cloud for visualisation: points (n, 3) [m] world frame, colours (n, 3) uint8.

    With ``crop`` the workspace box and the self-filter are applied (the table is kept);
    ``base`` as in :func:`object_points`.
    """
    params = params or PerceptionParams()
    region = crop_region(frame, params, base) if crop else None
    points, colors = points_from_depth(frame, params.max_depth, region)
    if crop:
        keep = crop_mask(points, params, base)
        points, colors = points[keep], colors[keep]
        keep = self_filter_mask(points, robot)
        points, colors = points[keep], colors[keep]
    return points, colors
