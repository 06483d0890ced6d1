"""One RGB-D frame's object points cut into clusters (ML perception, section 3.3).

The segmentation before the description (:mod:`~smccli.perception.clusters`): DBSCAN on
the points above the support planes, hidden parts attached to what hides them, parts split
by depth holes joined, and each point's place on its cluster's outline in the image.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from smccli.perception.cloud import (
    heights_above,
    object_pixels_on_planes,
    pixel_colours,
    support_plane,
)
from smccli.perception.dbscan import dbscan_labels
from smccli.perception.params import PerceptionParams
from smccli.world.sensors import CameraFrame, RobotGeometry


def cluster_labels(points: np.ndarray, params: PerceptionParams) -> np.ndarray:
    """DBSCAN labels, shape (n,) int; -1 = noise: open3d's ``cluster_dbscan``'s labels
    (:func:`~smccli.perception.dbscan.dbscan_labels`). Deterministic for a given input."""
    return dbscan_labels(points, params.dbscan_eps, params.dbscan_min_points)


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
    points: np.ndarray,
    labels: np.ndarray,
    frame: CameraFrame,
    params: PerceptionParams,
    projected: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Labels (n,) with each hidden part merged into the cluster that hides it.

    A mug's handle behind its body is seen past the rim, but the body hides the stretch
    that joins them (its occlusion shadow), so DBSCAN cuts the handle off as a cluster of
    its own. Cluster ``a`` joins cluster ``b`` when at least ``attach_min_contacts`` of
    its pixels touch (8-neighbourhood) pixels of ``b`` that are nearer the camera, with the
    two points within ``attach_gap`` of each other, ``a``'s top is lower than ``b``'s and
    ``a`` has at most ``attach_max_ratio`` times ``b``'s points.
    Touching in the image means nothing visible lies between them (no table); an object
    standing apart shows table in between. ``projected``: the points' :func:`_pixels`, if
    already made.
    """
    n_labels = int(labels.max(initial=-1)) + 1
    if n_labels < 2:
        return labels
    h, w = np.asarray(frame.depth).shape[:2]
    u, v, z = _pixels(points, frame) if projected is None else projected
    inside = (labels >= 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    idx = np.flatnonzero(inside)
    # A one-pixel border of no point: a neighbour's flat index is the pixel's plus a
    # constant, no bounds to test (as in :func:`outline_points`).
    index = np.full((h + 2) * (w + 2), -1, dtype=np.int64)
    at = (v[idx] + 1) * (w + 2) + (u[idx] + 1)
    index[at] = idx
    # Each unordered neighbour pair once, the four directions at once (4, m): the pairs
    # in the order of a loop over them, 0.1 ms less.
    step = np.array([dv * (w + 2) + du for du, dv in ((1, 0), (0, 1), (1, 1), (1, -1))])
    j = np.take(index, at + step[:, None])
    keep = j >= 0
    i, j = np.broadcast_to(idx, j.shape)[keep], j[keep]
    keep = labels[i] != labels[j]
    ij = np.stack([i[keep], j[keep]], axis=1)
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
        mine = points[idx]
        plane = support_of(mine, planes, params)
        if plane is not None and float(heights_above(mine, plane).min()) <= params.join_base:
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
    standing = []
    for k, idx, plane in standing_clusters(points, labels, planes, params, min_points=3):
        xy = points[idx, :2].astype(np.float64)
        # Its bounds column by column: ``xy.min(axis=0)`` loops over rows of two, ~10 times
        # slower (0.2 ms a decision); the same values.
        lo = np.array([xy[:, 0].min(), xy[:, 1].min()])
        standing.append((k, xy, plane, lo, np.array([xy[:, 0].max(), xy[:, 1].max()])))
    parent = np.arange(n_labels)

    def root(a: int) -> int:
        while parent[a] != a:
            a = int(parent[a])
        return a

    grow = max(int(round(params.join_margin / JOIN_CELL)), 0)
    for i, (a, xa, pa, la, ha) in enumerate(standing):
        for b, xb, pb, lb, hb in standing[i + 1 :]:
            if pa is not pb or root(a) == root(b):
                continue
            reach = 2 * params.join_margin
            if np.any(np.maximum(la, lb) - reach > np.minimum(ha, hb)):
                continue  # bounding boxes too far apart to overlap
            lo = np.minimum(la, lb) - reach
            cols, rows = (np.ceil((np.maximum(ha, hb) + reach - lo) / JOIN_CELL) + 1).astype(int)
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
    points: np.ndarray,
    labels: np.ndarray,
    frame: CameraFrame,
    params: PerceptionParams,
    projected: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Two masks (n,) of the points on their cluster's outline in the image, in one pass
    over the 8-neighbourhood of each point's pixel:

    - *cut* (:func:`cut_points`): a neighbour outside the cluster that is not
      ``silhouette_step`` farther from the camera, or the image's edge;
    - *occluded*: a neighbour of another label whose depth reading is ``silhouette_step``
      nearer, or the image's edge: something in front (the arm, another object) or the
      frame hides part of the object (:attr:`~smccli.perception.clusters.Cluster.hidden`).
      A neighbour level with it (an object touching it) or without a reading (a hole of a
      noisy depth camera) is not in front of it.

    ``projected``: the points' :func:`_pixels`, if already made.
    """
    depth = np.asarray(frame.depth)
    h, w = depth.shape[:2]
    u, v, z = _pixels(points, frame) if projected is None else projected
    ok = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    # Images with a one-pixel border (label -3, no reading): a neighbour's flat index is
    # the pixel's plus a constant, no bounds to test; 0.9 to 0.4 ms a decision.
    img = np.full((h + 2, w + 2), -3, dtype=np.int64)
    img[1:-1, 1:-1] = -2  # no object point (table, robot, crop)
    pad = np.full((h + 2, w + 2), np.nan, dtype=np.float32)
    pad[1:-1, 1:-1] = depth
    i = np.flatnonzero(ok)
    at = (v[i] + 1) * (w + 2) + (u[i] + 1)
    img.reshape(-1)[at] = labels[i]
    cut = ~ok
    occluded = ~ok
    lab, zi = labels[i], z[i]
    ahead, beyond = zi + params.silhouette_step, zi - params.silhouette_step
    # The eight neighbours at once (8, m): 0.18 to 0.08 ms a decision.
    step = np.array([dv * (w + 2) + du for du in (-1, 0, 1) for dv in (-1, 0, 1) if du or dv])
    nb = at + step[:, None]
    other = np.take(img.reshape(-1), nb)
    edge = other == -3  # the image's edge
    other = other != lab
    d = np.take(pad.reshape(-1), nb).astype(np.float64)
    finite = np.isfinite(d)
    behind = finite & (d > ahead)
    cut[i] |= np.any(other & ~behind, axis=0)
    nearer = finite & (d > 0) & (d < beyond)
    occluded[i] |= np.any((other & nearer) | edge, axis=0)
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
    """The table's points (m, 3) [m] and colours (m, 3) uint8 (relative brightness; none
    with it off)."""
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
    points, pixels, planes, (table, table_pixels) = object_pixels_on_planes(
        frame, robot, params, base
    )
    projected = _pixels(points, frame)
    labels = attach_hidden_parts(points, cluster_labels(points, params), frame, params, projected)
    labels = join_split_parts(points, labels, planes, params)
    cut, occluded = outline_points(points, labels, frame, params, projected)
    # The colours last: a simulated camera's may still be drawing until here (DrawingFrame).
    colors = pixel_colours(frame, pixels)
    table_colors = pixel_colours(frame, table_pixels)
    return Segmentation(points, colors, planes, (table, table_colors), labels, cut, occluded)
