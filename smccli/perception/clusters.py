"""Object clusters (ML perception, section 3.3): one RGB-D frame -> the objects on the table.

:func:`clusters_from_frame` segments the frame (:mod:`~smccli.perception.segment`) and
describes each cluster (:func:`describe_cluster`: box, symmetry, colours, brightness);
:func:`cluster_to_dict` / :func:`cluster_from_dict` keep a :class:`Cluster` in tree files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import cv2
import numpy as np
from scipy.spatial import cKDTree

from smccli.errors import TreeError
from smccli.perception.brightness import relative_brightness, side_points, sides_beneath
from smccli.perception.cloud import heights_above, in_crop_frame
from smccli.perception.histogram import hsv_histogram
from smccli.perception.params import PerceptionParams
from smccli.perception.segment import Segmentation, segment_frame, standing_clusters, support_of
from smccli.world.geometry import wrap
from smccli.world.sensors import CameraFrame, RobotGeometry


@dataclass(frozen=True, slots=True)
class Cluster:
    """One object seen on the table: a localized perception (value = look, location = pose)."""

    centroid: np.ndarray
    """Centre of the cluster's upright oriented box, shape (3,) [m], world frame: the
    footprint rectangle's centre in x-y, halfway between the table and the top in z (the
    mean of the visible points would lean towards the camera)."""
    yaw: float
    """Yaw about world z [rad], meaningful modulo ``yaw_period``: the footprint's longest
    horizontal axis in (-pi/2, pi/2] (elongated), a side's direction in [-pi/4, pi/4)
    (square), 0 (round), or the direction from the top's centre to the protrusion (e.g. a
    mug's handle) in (-pi, pi] (no symmetry)."""
    yaw_period: float
    """Symmetry of the footprint [rad]: pi elongated, pi/2 square, 0 round (yaw undefined),
    2 pi none (a protrusion on one side, e.g. a mug's handle)."""
    extents: np.ndarray
    """(length, width, height), shape (3,) [m]: footprint sides (length >= width), the
    protrusion included, and the top's height above the table plane."""
    histogram: np.ndarray
    """Colour histogram, shape (hue_bins * sat_bins + val_bins,), sums to 1
    (see :mod:`smccli.perception.histogram`)."""
    n_points: int
    """Number of points in the cluster (after the optional voxel downsampling); with it off,
    the object's area in the image [px]."""
    brightness: float = math.nan
    """Its side faces' brightness over the table's around it, dimensionless
    (:mod:`smccli.perception.brightness`); NaN without a table to compare with, and in
    trees from before it."""
    hidden: int = 0
    """Its points whose pixel borders something clearly nearer the camera (the arm, an
    object in front) or the image's edge: with ``hidden_min_points`` of them, part of it is
    out of sight, and its centre and extents are those of what is seen. Not stored in
    trees: a fact about the frame it came from."""
    crop_faces: tuple[str, ...] = ()
    """Faces of the perception's crop box the cluster's points reach (``x_min``, ...,
    ``z_max``, within ``crop_touch``): the box may cut the object there. Not stored in
    trees: a warning for record, doctor and compile."""

    @property
    def location(self) -> np.ndarray:
        """``[x, y, z, yaw]``, shape (4,) [m, m, m, rad]."""
        return np.r_[self.centroid, self.yaw]


def crop_faces(points: np.ndarray, lo: np.ndarray, hi: np.ndarray, touch: float) -> list[str]:
    """Faces of the box ``lo``..``hi`` that ``points`` (n, 3), in the box's frame, come
    within ``touch`` of: ``x_min``, ``x_max``, ``y_min``, ``y_max``, ``z_min``, ``z_max``."""
    if not len(points):
        return []
    # Column by column: the same extremes, a third of the (n, 3) reductions' time.
    low = [float(points[:, k].min()) for k in range(3)]
    high = [float(points[:, k].max()) for k in range(3)]
    faces = []
    for k, axis in enumerate("xyz"):
        if low[k] - lo[k] <= touch:
            faces.append(f"{axis}_min")
        if hi[k] - high[k] <= touch:
            faces.append(f"{axis}_max")
    return faces


def outside_hull(xy: np.ndarray, hull: np.ndarray) -> np.ndarray:
    """How far points (n, 2) lie outside a convex polygon ``hull`` (k, 2), shape (n,) [m].

    The largest signed distance to the polygon's edge lines: exact off an edge, a lower
    bound off a corner, negative inside. Vectorised over edges (a per-point
    ``cv2.pointPolygonTest`` loop is ~100 times slower).
    """
    edges = np.roll(hull, -1, axis=0) - hull
    normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    # Orient the normals outwards whatever the winding: the hull's mean is inside.
    inner = np.einsum("kj,kj->k", normals, hull.mean(axis=0) - hull)
    normals[inner > 0] *= -1
    # The two products of each (point, edge) and their sum, as ``np.einsum("kj,nkj->nk",
    # normals, xy[:, None, :] - hull[None])`` makes them (a sum of two is the same either
    # way round), without the (n, k, 2) differences: 0.7 to 0.45 ms for 3 k points; laid
    # out (k, n), edge by edge, the largest is taken across rows, not along rows of ~15:
    # 0.15 to 0.05 ms for a decision's 600.
    x, y = xy[:, 0].copy(), xy[:, 1].copy()
    out = (x - hull[:, 0:1]) * normals[:, 0:1]
    out += (y - hull[:, 1:2]) * normals[:, 1:2]
    return np.max(out, axis=0)


def _outside_top(xy: np.ndarray, top: np.ndarray) -> np.ndarray:
    """How far each point (n, 2) lies outside the top layer's (m, 2) convex hull, shape (n,)
    [m]; zeros when the top is a point or a line."""
    hull = cv2.convexHull(top.astype(np.float32))[:, 0, :].astype(np.float64)
    if len(hull) < 3 or cv2.contourArea(hull.astype(np.float32)) <= 0:
        return np.zeros(len(xy))
    return outside_hull(xy, hull)


def _spread(d: np.ndarray) -> float:
    """Circular standard deviation of the directions of vectors (n, 2) [rad]; inf if n = 0."""
    if len(d) == 0:
        return float("inf")
    u = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    r = float(np.linalg.norm(u.mean(axis=0)))  # mean resultant length
    return float(np.sqrt(-2.0 * np.log(max(r, 1e-12))))


def describe_cluster(
    points: np.ndarray,
    colors: np.ndarray,
    plane: np.ndarray | None,
    params: PerceptionParams,
    cut: np.ndarray | None = None,
) -> Cluster:
    """Location, extents, symmetry and histogram of one cluster's points (n, 3) [m].

    ``cut`` (n,) bool marks points whose pixel borders something hiding part of the object
    (:func:`~smccli.perception.segment.cut_points`); None = nothing is hidden.
    """
    heights = heights_above(points, plane)
    height = float(heights.max())
    xy = points[:, :2].astype(np.float64)
    # The camera sees the top and the near sides only, so the visible footprint of e.g. a
    # pyramid is a triangle. The top (a box's or cylinder's top face, a pyramid's apex) is
    # seen whole and lies over the footprint's centre: take the centre of the top layer,
    # and complete the footprint by point symmetry about it (exact for boxes, cylinders,
    # pyramids and cones, the objects of the built-in scenes).
    in_top = heights > height - params.top_band
    top = xy[in_top]
    (cx, cy), _, _ = cv2.minAreaRect(top.astype(np.float32))
    center = np.array([cx, cy])
    # A protrusion: points further than a margin outside the top's hull (the walls of
    # boxes and cylinders are within a pixel of it), enough of them, not most of the
    # cluster (a pyramid's top is its apex: nearly everything is outside), all on one side.
    # Such an object (a mug) has no symmetry and its protrusion is not mirrored.
    # Only with the top seen whole: if the arm hides part of it, the sides stick out.
    whole = cut is None or not bool(np.any(cut[in_top]))
    dist = _outside_top(xy, top) if whole else np.zeros(len(xy))
    far = dist > params.protrusion_margin
    n_far = int(far.sum())
    if (
        params.protrusion_min_points <= n_far <= params.protrusion_max_share * len(xy)
        and _spread(xy[far] - center) <= params.protrusion_max_spread
    ):
        return _describe_asymmetric(points, colors, plane, xy, center, far, dist, height, params)
    if n_far < params.protrusion_min_points:
        # A glimpse of a handle mostly hidden behind its body: mirroring it would invent a
        # second handle and an elongated footprint. Left out, the mug is seen as round.
        xy = xy[~far]
    xy = np.vstack([xy, 2.0 * center - xy]).astype(np.float32)
    rect = cv2.minAreaRect(xy)
    corners = cv2.boxPoints(rect).astype(np.float64)
    e1, e2 = corners[1] - corners[0], corners[2] - corners[1]
    l1, l2 = float(np.hypot(*e1)), float(np.hypot(*e2))
    long_edge = e1 if l1 >= l2 else e2
    length, width = max(l1, l2), min(l1, l2)
    # z of the table under the footprint centre.
    if plane is not None:
        base_z = float(-(plane[0] * cx + plane[1] * cy + plane[3]) / plane[2])
    else:
        base_z = float(points[:, 2].min())
    # Symmetry of the footprint: elongated -> pi; else a disc fills pi/4 of its square.
    if length > params.elongation_ratio * width:
        yaw_period = np.pi
    else:
        hull_area = cv2.contourArea(cv2.convexHull(xy))
        fill = hull_area / max(length * width, 1e-12)
        yaw_period = 0.0 if fill < params.round_fill else np.pi / 2
    if yaw_period == 0.0:
        yaw = 0.0
    elif yaw_period == np.pi:
        yaw = wrap(float(np.arctan2(long_edge[1], long_edge[0])), np.pi)
    else:  # square: report a side's direction in (-pi/4, pi/4], the period is pi/2
        yaw = wrap(float(np.arctan2(long_edge[1], long_edge[0])), np.pi / 2)
    return Cluster(
        centroid=np.array([cx, cy, base_z + height / 2]),
        yaw=yaw,
        yaw_period=float(yaw_period),
        extents=np.array([length, width, height]),
        histogram=hsv_histogram(colors, params),
        n_points=int(len(points)),
    )


def _describe_asymmetric(
    points: np.ndarray,
    colors: np.ndarray,
    plane: np.ndarray | None,
    xy: np.ndarray,
    center: np.ndarray,
    prot: np.ndarray,
    dist: np.ndarray,
    height: float,
    params: PerceptionParams,
) -> Cluster:
    """A cluster with a protrusion ``prot`` (mask (n,)) on one side of its top's ``center``;
    ``dist`` (n,) [m] is each point's distance outside the top's convex hull.

    Yaw points from the top's centre to the protrusion; the footprint is the body's points
    completed by point symmetry plus the rest, boxed along the yaw.
    """
    d = xy[prot] - center
    yaw = float(np.arctan2(d[:, 1].mean(), d[:, 0].mean()))
    # The camera sees the protrusion's near side face as well as its top, which pulls the
    # mean sideways; the middle of its lateral extent does not lean (its top is seen whole).
    c, s = np.cos(yaw), np.sin(yaw)
    along, across = d[:, 0] * c + d[:, 1] * s, d[:, 1] * c - d[:, 0] * s
    yaw = wrap(yaw + float(np.arctan2(0.5 * (across.max() + across.min()), along.mean())))
    # The body is what lies over the top's hull (walls are within a pixel, 3-6 mm, of it);
    # mirroring the handle's root, 5-10 mm out, would lengthen the far side.
    near = dist <= 0.5 * params.protrusion_margin
    body = xy[near]
    foot = np.vstack([body, 2.0 * center - body, xy[~near]]) - center
    c, s = np.cos(yaw), np.sin(yaw)
    along, across = foot[:, 0] * c + foot[:, 1] * s, foot[:, 1] * c - foot[:, 0] * s
    a0, a1, b0, b1 = along.min(), along.max(), across.min(), across.max()
    mid = center + 0.5 * (a0 + a1) * np.array([c, s]) + 0.5 * (b0 + b1) * np.array([-s, c])
    if plane is not None:
        base_z = float(-(plane[0] * mid[0] + plane[1] * mid[1] + plane[3]) / plane[2])
    else:
        base_z = float(points[:, 2].min())
    sides = sorted((float(a1 - a0), float(b1 - b0)), reverse=True)
    return Cluster(
        centroid=np.array([mid[0], mid[1], base_z + height / 2]),
        yaw=yaw,
        yaw_period=2.0 * np.pi,
        extents=np.array([sides[0], sides[1], height]),
        histogram=hsv_histogram(colors, params),
        n_points=int(len(points)),
    )


def describe_points(
    seg: Segmentation,
    idx: np.ndarray,
    params: PerceptionParams,
    base: np.ndarray | None,
    around: np.ndarray | None = None,
) -> Cluster:
    """The cluster of points ``idx`` (k,) of ``seg``: :func:`describe_cluster` with its
    brightness, the points hidden by something in front and the crop box's faces it
    reaches. ``around``: for a piece of a cluster, that cluster's points (indices of
    ``seg``), whose side faces beneath the piece give its brightness where its own are
    too few (:func:`~smccli.perception.brightness.sides_beneath`)."""
    points, colors = seg.points[idx], seg.colors[idx]
    plane = support_of(points, seg.planes, params)
    cluster = describe_cluster(points, colors, plane, params, seg.cut[idx])
    brightness = cluster.brightness
    if params.brightness_scale > 0:
        side = side_points(heights_above(points, plane))
        brightness = relative_brightness(points, colors, side, *seg.table, params)
        if math.isnan(brightness) and around is not None and plane is not None:
            top = float(heights_above(points, plane).max(initial=0.0))
            near = seg.points[around]
            side = sides_beneath(points, near, heights_above(near, plane), top)
            brightness = relative_brightness(near, seg.colors[around], side, *seg.table, params)
    cluster = replace(cluster, brightness=brightness, hidden=int(seg.occluded[idx].sum()))
    faces = crop_faces(
        in_crop_frame(points, params, base),
        np.asarray(params.crop_min),
        np.asarray(params.crop_max),
        params.crop_touch,
    )
    return replace(cluster, crop_faces=tuple(faces)) if faces else cluster


def _sorted(clusters: list[Cluster]) -> tuple[Cluster, ...]:
    return tuple(sorted(clusters, key=lambda c: (float(c.centroid[0]), float(c.centroid[1]))))


def clusters_from_frame(
    frame: CameraFrame,
    robot: RobotGeometry | None,
    params: PerceptionParams | None = None,
    base: np.ndarray | None = None,
) -> tuple[Cluster, ...]:
    """The object clusters in one RGB-D frame (ML perception, eq. 14).

    :func:`segment_frame`, then per cluster (:func:`describe_points`): histogram, box
    centre, yaw, symmetry, extents. Sorted by centroid x, then y. Uses only the images and
    the robot's own geometry (and a mobile manipulator's ``base`` pose from odometry, where
    its crop box is).
    """
    params = params or PerceptionParams()
    seg = segment_frame(frame, robot, params, base)
    found = []
    for k in range(int(seg.labels.max(initial=-1)) + 1):
        idx = np.flatnonzero(seg.labels == k)
        if len(idx) >= params.min_cluster_points:
            found.append(describe_points(seg, idx, params, base))
    return _sorted(found)


def cluster_unions(
    frame: CameraFrame,
    robot: RobotGeometry | None,
    params: PerceptionParams,
    base: np.ndarray | None = None,
) -> tuple[Cluster, ...]:
    """Each pair of neighbouring clusters of one frame described as one object: what an
    object seen in pieces would look like.

    Where a thin wall in front hides the stretch between two parts of an object (an open
    box's near wall and its floor, seen past the rim across a band of depth holes), no
    geometry tells the parts from two objects one behind the other; the SMC's taught
    perception can (:meth:`~smccli.execute.policy.TreePolicy.match` tries these only where
    no single cluster is contingent). Neighbours stand on the same surface (within
    ``join_base``) with footprints at most ``piece_gap`` apart. Sorted like
    :func:`clusters_from_frame`.
    """
    seg = segment_frame(frame, robot, params, base)
    parts = [
        (idx, plane, cKDTree(seg.points[idx, :2]))
        for _, idx, plane in standing_clusters(
            seg.points, seg.labels, seg.planes, params, params.min_cluster_points
        )
    ]
    found = []
    for i, (ia, pa, ta) in enumerate(parts):
        for ib, pb, tb in parts[i + 1 :]:
            if pa is not pb:
                continue
            gap = ta.sparse_distance_matrix(tb, params.piece_gap, output_type="ndarray")
            if len(gap):
                found.append(describe_points(seg, np.concatenate([ia, ib]), params, base))
    return _sorted(found)


def _json(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    return value


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


_STORED = tuple(f for f in fields(Cluster) if f.name not in ("crop_faces", "hidden"))
"""The fields a tree keeps: ``crop_faces`` and ``hidden`` are facts about the frame it came
from."""
_OPTIONAL = {"brightness": math.nan}
"""Stored fields a tree may lack (from before them), with the value they then take; a NaN
is left out of the file (JSON has no NaN)."""


def cluster_to_dict(c: Cluster) -> dict[str, Any]:
    """JSON-ready form of a cluster (lists of floats), for tree files and logs."""
    out = {f.name: _json(getattr(c, f.name)) for f in _STORED}
    return {k: v for k, v in out.items() if not (k in _OPTIONAL and math.isnan(v))}


def cluster_from_dict(data: dict[str, Any]) -> Cluster:
    """Inverse of :func:`cluster_to_dict`; arrays come back as float arrays.

    TreeError for a value that is not a number (array fields: a list of numbers;
    ``np.asarray`` would turn the string ``"inf"`` into a float) and for a centroid or
    extents not of length 3.
    """
    kwargs: dict[str, Any] = {}
    for f in _STORED:
        if f.name not in data and f.name in _OPTIONAL:
            continue
        v = data[f.name]
        if f.type == "np.ndarray":  # annotations are strings (``from __future__``)
            if not (isinstance(v, list) and all(_is_number(x) for x in v)):
                raise TreeError(f"cluster {f.name}: expected a list of numbers")
            kwargs[f.name] = np.asarray(v, dtype=float)
        elif _is_number(v):
            kwargs[f.name] = v
        else:
            raise TreeError(f"cluster {f.name}: expected a number")
    for name, shape in (("centroid", (3,)), ("extents", (3,))):
        if np.shape(kwargs[name]) != shape:
            raise TreeError(f"cluster {name}: expected 3 numbers, found {kwargs[name]!r:.60}")
    return Cluster(**kwargs)
