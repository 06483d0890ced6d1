"""Object clusters (ML perception, section 3.3): one RGB-D frame -> the objects on the table."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import cv2
import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from smccli.perception.brightness import relative_brightness, side_points
from smccli.perception.cloud import (
    crop_faces,
    in_crop_frame,
    object_points_on_planes,
    plane_distance,
    support_plane,
)
from smccli.perception.histogram import hsv_histogram
from smccli.perception.params import PerceptionParams
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
    return np.max(np.einsum("kj,nkj->nk", normals, xy[:, None, :] - hull[None]), axis=1)


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


def heights_above(points: np.ndarray, plane: np.ndarray | None) -> np.ndarray:
    """Height of points (n, 3) above the table plane, shape (n,) [m]; without a plane,
    above the lowest point."""
    return plane_distance(points, plane) if plane is not None else points[:, 2] - points[:, 2].min()


def describe_cluster(
    points: np.ndarray,
    colors: np.ndarray,
    plane: np.ndarray | None,
    params: PerceptionParams,
    cut: np.ndarray | None = None,
) -> Cluster:
    """Location, extents, symmetry and histogram of one cluster's points (n, 3) [m].

    ``cut`` (n,) bool marks points whose pixel borders something hiding part of the object
    (:func:`cut_points`); None = nothing is hidden.
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


def cluster_labels(points: np.ndarray, params: PerceptionParams) -> np.ndarray:
    """DBSCAN labels (open3d), shape (n,) int; -1 = noise. Deterministic for a given input."""
    if len(points) == 0:
        return np.zeros(0, dtype=np.int64)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    return np.asarray(
        pcd.cluster_dbscan(eps=params.dbscan_eps, min_points=params.dbscan_min_points),
        dtype=np.int64,
    )


def _pixels(points: np.ndarray, frame: CameraFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Image column, row (n,) int and depth (n,) [m] of world points (n, 3): the pixels
    they were lifted from."""
    T = np.asarray(frame.T_world_camera, dtype=np.float64)
    K = np.asarray(frame.K, dtype=np.float64)
    p = np.einsum("ji,nj->ni", T[:3, :3], points - T[:3, 3])  # R^T (p - t), optical frame
    z = p[:, 2]
    y_n, x_n = p[:, 1] / z, p[:, 0] / z
    u = np.rint(K[0, 0] * x_n + K[0, 1] * y_n + K[0, 2]).astype(np.int64)
    v = np.rint(K[1, 1] * y_n + K[1, 2]).astype(np.int64)
    return u, v, z


def attach_hidden_parts(
    points: np.ndarray, labels: np.ndarray, frame: CameraFrame, params: PerceptionParams
) -> np.ndarray:
    """Labels (n,) with each hidden part merged into the cluster that hides it.

    A mug's handle behind its body is seen past the rim, but the body hides the stretch
    that joins them (its occlusion shadow), so DBSCAN cuts the handle off as a cluster of
    its own. Cluster ``a`` joins cluster ``b`` when at least ``attach_min_contacts`` of
    its pixels touch (8-neighbourhood) pixels of ``b`` that are nearer the camera, with the
    two points within ``attach_gap`` of each other, ``a``'s top is lower than ``b``'s and
    ``a`` has at most ``attach_max_ratio`` times ``b``'s points.
    Touching in the image means nothing visible lies between them (no table); an object
    standing apart shows table in between.
    """
    n_labels = int(labels.max(initial=-1)) + 1
    if n_labels < 2:
        return labels
    h, w = np.asarray(frame.depth).shape[:2]
    u, v, z = _pixels(points, frame)
    inside = (labels >= 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    index = np.full((h, w), -1, dtype=np.int64)
    index[v[inside], u[inside]] = np.flatnonzero(inside)
    idx = np.flatnonzero(inside)
    pairs = []
    for du, dv in ((1, 0), (0, 1), (1, 1), (1, -1)):  # each unordered neighbour pair once
        uu, vv = u[idx] + du, v[idx] + dv
        ok = (uu >= 0) & (uu < w) & (vv >= 0) & (vv < h)
        i = idx[ok]
        j = index[vv[ok], uu[ok]]
        keep = j >= 0
        i, j = i[keep], j[keep]
        keep = labels[i] != labels[j]
        pairs.append(np.stack([i[keep], j[keep]], axis=1))
    ij = np.concatenate(pairs)
    if len(ij) == 0:
        return labels
    # Order each pair as (farther, nearer) and keep those bridging a small gap.
    far_first = z[ij[:, 0]] >= z[ij[:, 1]]
    ij = np.where(far_first[:, None], ij, ij[:, ::-1])
    gap = np.linalg.norm(points[ij[:, 0]] - points[ij[:, 1]], axis=1)
    ij = ij[gap < params.attach_gap]
    tops = np.full(n_labels, -np.inf)
    np.maximum.at(tops, labels[labels >= 0], points[labels >= 0, 2])
    sizes = np.bincount(labels[labels >= 0], minlength=n_labels)
    contacts = np.zeros((n_labels, n_labels), dtype=np.int64)
    np.add.at(contacts, (labels[ij[:, 0]], labels[ij[:, 1]]), 1)
    parent = np.arange(n_labels)
    for a in range(n_labels):
        b = int(np.argmax(contacts[a]))
        if (
            contacts[a, b] >= params.attach_min_contacts
            and tops[a] < tops[b]
            and sizes[a] <= params.attach_max_ratio * sizes[b]
        ):
            parent[a] = b
    # Follow chains (a part of a part); tops strictly increase along them, so they end.
    for _ in range(n_labels):
        parent = parent[parent]
    out = labels.copy()
    out[labels >= 0] = parent[labels[labels >= 0]]
    return out


def _footprint_mask(
    xy: np.ndarray, origin: np.ndarray, shape: tuple[int, int], grow: int
) -> np.ndarray:
    """The convex hull of points ``xy`` (n, 2) [m] rasterised at :data:`JOIN_CELL` on a
    grid of ``shape`` whose cell (0, 0) is at ``origin``, dilated by ``grow`` cells."""
    mask = np.zeros(shape, dtype=np.uint8)
    cells = np.rint((xy - origin) / JOIN_CELL).astype(np.int32)
    cv2.fillConvexPoly(mask, cv2.convexHull(cells), 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * grow + 1, 2 * grow + 1))
    return cv2.dilate(mask, kernel).astype(bool)


JOIN_CELL = 0.002
"""Grid cell of the footprint overlap in :func:`join_split_parts` [m]: a fifth of the
thinnest wall of the built-in objects."""


def support_of(
    points: np.ndarray, planes: list[np.ndarray], params: PerceptionParams
) -> np.ndarray | None:
    """The plane ``points`` (n, 3) stand on: on a tabletop its one table; among shelves
    and cabinet tops (``remove_walls``), the one just below them."""
    if params.remove_walls:
        return support_plane(points, planes)
    return planes[0] if planes else None


def standing_clusters(
    points: np.ndarray,
    labels: np.ndarray,
    planes: list[np.ndarray],
    params: PerceptionParams,
    min_points: int,
) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """(label, point indices, support plane) of each cluster of at least ``min_points``
    that reaches down to within ``join_base`` of the plane it stands on: what stands on a
    surface, not what is held above it."""
    out = []
    for k in range(int(labels.max(initial=-1)) + 1):
        idx = np.flatnonzero(labels == k)
        if len(idx) < min_points:
            continue
        plane = support_of(points[idx], planes, params)
        if plane is not None and float(heights_above(points[idx], plane).min()) <= params.join_base:
            out.append((k, idx, plane))
    return out


def join_split_parts(
    points: np.ndarray,
    labels: np.ndarray,
    planes: list[np.ndarray],
    params: PerceptionParams,
) -> np.ndarray:
    """Labels (n,) with the parts of one object that depth holes split apart merged.

    A noisy depth camera loses the pixels along depth edges; an open box's 1 cm walls are
    nothing but edges, so its floor (seen past the near rim) and its near walls fall apart
    into clusters DBSCAN cannot join. Two objects standing on one surface never share floor
    space, so clusters standing on the same support plane (each reaching down to within
    ``join_base`` of it) whose footprints, grown by ``join_margin``, overlap by
    ``join_overlap`` of the smaller one's are one object. An object held above another
    does not reach down to the surface and stays apart.
    """
    n_labels = int(labels.max(initial=-1)) + 1
    if n_labels < 2:
        return labels
    standing = [
        (k, points[idx, :2].astype(np.float64), plane)
        for k, idx, plane in standing_clusters(points, labels, planes, params, min_points=3)
    ]
    parent = np.arange(n_labels)

    def root(a: int) -> int:
        while parent[a] != a:
            a = int(parent[a])
        return a

    grow = max(int(round(params.join_margin / JOIN_CELL)), 0)
    for i, (a, xa, pa) in enumerate(standing):
        for b, xb, pb in standing[i + 1 :]:
            if pa is not pb or root(a) == root(b):
                continue
            reach = 2 * params.join_margin
            if np.any(
                np.maximum(xa.min(axis=0), xb.min(axis=0)) - reach
                > np.minimum(xa.max(axis=0), xb.max(axis=0))
            ):
                continue  # bounding boxes too far apart to overlap
            lo = np.minimum(xa.min(axis=0), xb.min(axis=0)) - reach
            cols, rows = (
                np.ceil((np.maximum(xa.max(axis=0), xb.max(axis=0)) + reach - lo) / JOIN_CELL) + 1
            ).astype(int)
            shape = (int(rows), int(cols))
            ma = _footprint_mask(xa, lo, shape, grow)
            mb = _footprint_mask(xb, lo, shape, grow)
            shared = np.count_nonzero(ma & mb)
            if shared >= params.join_overlap * min(ma.sum(), mb.sum()):
                parent[root(b)] = root(a)
    roots = np.array([root(k) for k in range(n_labels)])
    out = labels.copy()
    out[labels >= 0] = roots[labels[labels >= 0]]
    return out


def cut_points(
    points: np.ndarray, labels: np.ndarray, frame: CameraFrame, params: PerceptionParams
) -> np.ndarray:
    """Points (n,) whose pixel borders (8-neighbourhood) a pixel outside their cluster that
    is not ``silhouette_step`` farther from the camera, or the image's edge.

    An object's outline in the image borders only what lies behind it (the table) or the
    object itself; anything else nearer or level with it (an occluder, pixels removed by
    the self-filter or the crop) hides part of it.
    """
    return outline_points(points, labels, frame, params)[0]


def outline_points(
    points: np.ndarray, labels: np.ndarray, frame: CameraFrame, params: PerceptionParams
) -> tuple[np.ndarray, np.ndarray]:
    """Two masks (n,) of the points on their cluster's outline in the image, in one pass
    over the 8-neighbourhood of each point's pixel:

    - *cut* (:func:`cut_points`): a neighbour outside the cluster that is not
      ``silhouette_step`` farther from the camera, or the image's edge;
    - *occluded*: a neighbour of another label whose depth reading is ``silhouette_step``
      nearer, or the image's edge: something in front (the arm, another object) or the
      frame hides part of the object (:attr:`Cluster.hidden`). A neighbour level with it
      (an object touching it) or without a reading (a hole of a noisy depth camera) is not
      in front of it.
    """
    depth = np.asarray(frame.depth, dtype=np.float64)
    h, w = depth.shape[:2]
    u, v, z = _pixels(points, frame)
    img = np.full((h, w), -2, dtype=np.int64)  # -2: no object point (table, robot, crop)
    ok = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    img[v[ok], u[ok]] = labels[ok]
    cut = ~ok
    occluded = ~ok
    for du in (-1, 0, 1):
        for dv in (-1, 0, 1):
            if du == 0 and dv == 0:
                continue
            uu, vv = u + du, v + dv
            inside = ok & (uu >= 0) & (uu < w) & (vv >= 0) & (vv < h)
            cut |= ok & ~inside  # at the image's edge
            occluded |= ok & ~inside
            i = np.flatnonzero(inside)
            d = depth[vv[i], uu[i]]
            other = img[vv[i], uu[i]] != labels[i]
            behind = np.isfinite(d) & (d > z[i] + params.silhouette_step)
            cut[i] |= other & ~behind
            nearer = np.isfinite(d) & (d > 0) & (d < z[i] - params.silhouette_step)
            occluded[i] |= other & nearer
    return cut, occluded


@dataclass(frozen=True, slots=True)
class Segmentation:
    """One frame's object points and their clusters: what the clusters are described from."""

    points: np.ndarray
    """Object points standing on the table, shape (n, 3) [m], world frame."""
    colors: np.ndarray
    """Their colours, shape (n, 3) uint8 RGB."""
    planes: list[np.ndarray]
    """Support planes ``[a, b, c, d]`` found (the table first)."""
    table: tuple[np.ndarray, np.ndarray]
    """The table's points (m, 3) [m] and colours (m, 3) uint8 (relative brightness)."""
    labels: np.ndarray
    """Cluster of each point, shape (n,) int; -1 = noise."""
    cut: np.ndarray
    """Points (n,) bordering something that hides part of their object (:func:`cut_points`)."""
    occluded: np.ndarray
    """Points (n,) bordering something in front of them (:func:`outline_points`)."""


def segment_frame(
    frame: CameraFrame,
    robot: RobotGeometry | None,
    params: PerceptionParams,
    base: np.ndarray | None = None,
) -> Segmentation:
    """depth -> world points -> crop -> self-filter (``robot``'s spheres) -> table plane
    removal (RANSAC) -> DBSCAN -> hidden parts joined to the cluster hiding them -> parts
    split by depth holes joined (:func:`join_split_parts`) -> outlines."""
    points, colors, planes, table = object_points_on_planes(frame, robot, params, base)
    labels = attach_hidden_parts(points, cluster_labels(points, params), frame, params)
    labels = join_split_parts(points, labels, planes, params)
    cut, occluded = outline_points(points, labels, frame, params)
    return Segmentation(points, colors, planes, table, labels, cut, occluded)


def describe_points(
    seg: Segmentation, idx: np.ndarray, params: PerceptionParams, base: np.ndarray | None
) -> Cluster:
    """The cluster of points ``idx`` (k,) of ``seg``: :func:`describe_cluster` with its
    brightness, the points hidden by something in front and the crop box's faces it
    reaches."""
    points, colors = seg.points[idx], seg.colors[idx]
    plane = support_of(points, seg.planes, params)
    cluster = describe_cluster(points, colors, plane, params, seg.cut[idx])
    brightness = cluster.brightness
    if params.brightness_scale > 0:
        side = side_points(heights_above(points, plane))
        brightness = relative_brightness(points, colors, side, *seg.table, params)
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
    from smccli.errors import TreeError

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
