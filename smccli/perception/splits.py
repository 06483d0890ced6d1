"""Objects touching one another seen as one cluster, divided again (issue 38).

Two objects standing closer than DBSCAN's reach (``dbscan_eps``) are one cluster: a white
box with a grey box of its size against it reads as one 25 x 14 cm object, which matches
no taught view. Where one ends shows in what differs between them: brightness or height
(even within one frame of a camera whose exposure and white balance drift), or, for two
bars meeting at an angle, the direction the footprint runs in around each point:
:func:`cluster_splits` divides each cluster by each of these
(:func:`split_masks`), keeps each side's connected pieces, and describes each piece as an
object of its own (:func:`~smccli.perception.clusters.describe_points`). The SMC's taught
perception then says whether a piece is the taught object
(:func:`~smccli.execute.matching.match_arm` tries these only where no single cluster, nor
a union of two, is contingent), the mirror image of
:func:`~smccli.perception.clusters.cluster_unions`. Where no piece is either,
:func:`cluster_windows` takes the parts of the taught size at either end and side of a
cluster or piece longer, wider or shorter than the taught object: a look-alike end to end
or side by side with the white box joins its piece, or takes part of it.
"""

from __future__ import annotations

import itertools

import cv2
import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

from smccli.perception.cloud import heights_above
from smccli.perception.clusters import Cluster, describe_points
from smccli.perception.params import PerceptionParams
from smccli.perception.segment import Segmentation, cluster_labels, segment_frame, standing_clusters
from smccli.world.geometry import to_frame
from smccli.world.sensors import CameraFrame, RobotGeometry

TOP_RADIUS = 0.015
"""Radius of the neighbourhood whose highest point is a point's *local top* [m]: a side
face's points then carry their own object's top height (a box's side is 4-7 cm wide),
so two objects of different heights fall apart by it."""
MIN_STEP = 0.003
"""Smallest difference of the two sides' mean local top for a height split [m]: the
depth camera's noise on a flat top is about 1 mm."""
DIRECTION_RADIUS = 0.03
"""Radius of the neighbourhood whose footprint gives a point's *local direction* [m]: more
than half a box's width, so that across a bar's whole width the neighbourhood is cut by
its sides and runs along it (at 2 cm, half a 4 cm bar's width, the centre line's was a
whole disc, with no direction)."""
MIN_DIRECTION_STEP = 20
"""Smallest difference of the two sides' mean local direction for a direction split, on
0-255 for a half turn (20: 14 degrees)."""
LONGER = 1.1
"""A cluster or piece at least this much longer than a taught object is looked into for
it (:func:`cluster_windows`): the depth camera's length error is a few percent."""
MIN_BRIGHTNESS_STEP = 20
"""Smallest difference of the two sides' mean brightness for a brightness split (0-255):
one object's top and sides differ by more, which is why every piece only ever is a
candidate for the taught perception to judge."""


def otsu_split(values: np.ndarray, min_step: float) -> np.ndarray | None:
    """Mask (n,) of the upper side of Otsu's threshold of ``values`` (n,) in 0-255 (the
    best two-means split of one feature), or None where the two sides' means differ by
    less than ``min_step``."""
    v = np.clip(np.rint(values), 0, 255).astype(np.uint8).reshape(-1, 1)
    t, _ = cv2.threshold(v, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    upper = v[:, 0] > t
    if upper.all() or not upper.any():
        return None
    if float(v[upper].mean()) - float(v[~upper].mean()) < min_step:
        return None
    return upper


def split_masks(
    points: np.ndarray, colors: np.ndarray, plane: np.ndarray | None
) -> list[np.ndarray]:
    """Ways to divide one cluster's points (n, 3) [m] with colours (n, 3) uint8 in two,
    masks (n,): by brightness (max(R, G, B): a white box's clipped top against a grey
    one's), by local direction (:func:`local_direction`: two bars at an angle) and by each
    point's local top above ``plane`` (:data:`TOP_RADIUS`: one object taller than the
    other). Chroma (max - min) divided none of the 46 merged white box
    and look-alike clusters of seed 0 usefully (docs/perception.md) and is left out."""
    masks = [otsu_split(colors.max(axis=1).astype(np.float64), MIN_BRIGHTNESS_STEP)]
    masks.append(otsu_split(local_direction(points), MIN_DIRECTION_STEP))
    if plane is not None:
        h = heights_above(points, plane)
        near = cKDTree(points[:, :2]).query_ball_point(points[:, :2], TOP_RADIUS)
        top = np.array([h[j].max() for j in near])
        masks.append(otsu_split(top * 1000.0, MIN_STEP * 1000.0))  # in mm: 0-255
    return [m for m in masks if m is not None]


def local_direction(points: np.ndarray) -> np.ndarray:
    """Each point's local direction on 0-255 (n,): the longest axis of the footprint of its
    :data:`DIRECTION_RADIUS` neighbourhood (points (n, 3) [m], x-y), as a doubled angle
    from the cluster's mean one (a half turn is the same direction). Two bars touching end
    to end at an angle (an L, a V) fall apart by it where brightness and height do not:
    their tops clip alike, and a look-alike may be as tall."""
    xy = points[:, :2] - points[:, :2].mean(axis=0)
    n = len(xy)
    pairs = cKDTree(xy).query_pairs(DIRECTION_RADIUS, output_type="ndarray")
    i = np.r_[pairs[:, 0], pairs[:, 1], np.arange(n)]
    j = np.r_[pairs[:, 1], pairs[:, 0], np.arange(n)]
    # Neighbourhood sums of 1, x, y, x², xy, y² as one sparse product.
    near = csr_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
    s = near @ np.c_[np.ones(n), xy, xy[:, 0] ** 2, xy[:, 0] * xy[:, 1], xy[:, 1] ** 2]
    m = s[:, 0]
    mx, my = s[:, 1] / m, s[:, 2] / m
    a = s[:, 3] / m - mx * mx - (s[:, 5] / m - my * my)  # var(x) - var(y)
    b = 2 * (s[:, 4] / m - mx * my)  # 2 cov(x, y)
    doubled = np.arctan2(b, a)
    weight = np.hypot(a, b)  # how elongated: a round neighbourhood has no direction
    mean = np.arctan2((weight * np.sin(doubled)).sum(), (weight * np.cos(doubled)).sum())
    off = np.angle(np.exp(1j * (doubled - mean)))  # (-pi, pi], the cut opposite the mean
    return (off + np.pi) / (2 * np.pi) * 255.0


def split_parts(
    seg: Segmentation,
    idx: np.ndarray,
    plane: np.ndarray | None,
    params: PerceptionParams,
    local: bool = False,
) -> list[np.ndarray]:
    """The pieces ``idx`` (k,) of ``seg`` divides into: each side of each of
    :func:`split_masks`, cut into its connected pieces (DBSCAN with the scene's own
    parameters), those of at least ``min_cluster_points``; no piece twice. Each piece
    indexes ``seg``'s points, or with ``local`` ``idx``."""
    out: list[np.ndarray] = []
    seen: set[bytes] = set()
    for mask in split_masks(seg.points[idx], seg.colors[idx], plane):
        for side in np.flatnonzero(mask), np.flatnonzero(~mask):
            labels = cluster_labels(seg.points[idx[side]], params)
            for k in range(int(labels.max(initial=-1)) + 1):
                part = side[labels == k]
                key = part.tobytes()
                if len(part) >= params.min_cluster_points and key not in seen:
                    seen.add(key)
                    out.append(part if local else idx[part])
    return out


def cluster_splits(
    frame: CameraFrame,
    robot: RobotGeometry | None,
    params: PerceptionParams,
    base: np.ndarray | None = None,
) -> tuple[Cluster, ...]:
    """The pieces each standing cluster of one frame divides into (:func:`split_parts`),
    each described as one object: what each of two touching objects would look like.
    Clusters too small to hold two objects (under twice ``min_cluster_points``) are left
    whole. Sorted like :func:`~smccli.perception.clusters.clusters_from_frame`."""
    seg = segment_frame(frame, robot, params, base)
    found = []
    for _, idx, plane in standing_clusters(
        seg.points, seg.labels, seg.planes, params, 2 * params.min_cluster_points
    ):
        for part in split_parts(seg, idx, plane, params):
            found.append(describe_points(seg, part, params, base, around=idx))
    return tuple(sorted(found, key=lambda c: (float(c.centroid[0]), float(c.centroid[1]))))


def cluster_windows(
    frame: CameraFrame,
    robot: RobotGeometry | None,
    params: PerceptionParams,
    base: np.ndarray | None = None,
    sizes: tuple[tuple[float, float], ...] = (),
    ends_only: bool = True,
    unknown_brightness: bool = True,
) -> tuple[Cluster, ...]:
    """The parts of the taught size of each standing cluster and each of its pieces
    (:func:`split_parts`) whose size differs from a taught object's, each described as one
    object: for each taught (length, width) of ``sizes`` [m], :func:`windows` (the ends of
    those too long alone, or every other window). Without ``unknown_brightness``, a window
    whose brightness is unknown is left out: a window is a guess, and the side windows of
    look-alikes (0.58-0.64) of unknown brightness passed for the box where the box's did
    not (seed 5's 125, seed 6's 177).

    A look-alike touching the white box end to end is joined to it by every split where
    its end reads as bright as the box: the white piece is 16-20 cm long where 14 were
    taught, and nothing is contingent (development seed 2's 48, 156 and 196). The box is
    then the part of that piece as long as the taught box, at the end away from the
    look-alike. One along its side joins the near side's points: the piece is 5-7 cm wide
    where 4 were taught (seed 0's 107, seed 6's 118 and 177); one against its end may take
    the box's end: the piece is 11 cm long (seed 5's 3). The taught perception says which
    window, if any, is the box."""
    seg = segment_frame(frame, robot, params, base)
    found = []
    for _, idx, plane in standing_clusters(
        seg.points, seg.labels, seg.planes, params, params.min_cluster_points
    ):
        xy = seg.points[idx, :2]
        for part in [np.arange(len(idx)), *split_parts(seg, idx, plane, params, local=True)]:
            whole = describe_points(seg, idx[part], params, base)
            if whole.yaw_period != np.pi:
                continue
            for window in windows(xy, part, whole.yaw, whole.extents[:2], sizes, ends_only):
                if len(window) < params.min_cluster_points:
                    continue
                view = describe_points(seg, idx[window], params, base, around=idx)
                if unknown_brightness or not np.isnan(view.brightness):
                    found.append(view)
    return tuple(sorted(found, key=lambda c: (float(c.centroid[0]), float(c.centroid[1]))))


def _off_size(extent: float, taught: float) -> int:
    """1 where ``extent`` is :data:`LONGER` than ``taught``, -1 shorter, else 0."""
    return int(extent >= LONGER * taught) - int(LONGER * extent <= taught)


def windows(
    xy: np.ndarray,
    part: np.ndarray,
    yaw: float,
    extents: np.ndarray,
    sizes: tuple[tuple[float, float], ...],
    ends_only: bool = False,
) -> list[np.ndarray]:
    """The windows (index arrays into ``xy``) of the piece ``part`` (indices) of one
    cluster's points ``xy`` (n, 2) [m]; the piece's length runs along ``yaw`` [rad], its
    (length, width) is ``extents`` [m]. For each taught (length, width) of ``sizes`` [m],
    along its length or across its width: a piece :data:`LONGER` than taught gives its
    points within the taught size of either end (or side); one shorter, the cluster's
    points in the piece's band from either end over the taught size (the part of the box
    a look-alike against it took). ``ends_only``: only the ends of a piece too long; else
    every window but those, each of a piece whose other size is about right: a window cut
    across a merged cluster (22 x 15 cm), over the ends of a white box and a look-alike in
    a V, passed for the box (development seed 0's 107)."""
    uv = to_frame((0.0, 0.0, yaw), xy)  # along the piece's length, across it
    lo, hi = uv[part].min(axis=0), uv[part].max(axis=0)
    out = []
    for size, k in itertools.product(sizes, (0,) if ends_only else (0, 1)):
        off = [_off_size(e, t) for e, t in zip(extents[:2], size, strict=True)]
        if off[k] == 0 or (k == 0 and (off[k] > 0) != ends_only) or (off[1 - k] and not ends_only):
            continue
        longer = off[k] > 0
        if longer:
            pts = part
        else:  # the cluster's points in the piece's band
            j = 1 - k
            pts = np.flatnonzero((uv[:, j] >= lo[j]) & (uv[:, j] <= hi[j]))
        for start in (lo[k], hi[k] - size[k]):
            out.append(pts[(uv[pts, k] >= start) & (uv[pts, k] <= start + size[k])])
    return out
