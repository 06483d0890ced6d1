"""Objects touching one another seen as one cluster, divided again (issue 38).

Two objects standing closer than DBSCAN's reach (``dbscan_eps``) are one cluster: a white
box with a grey box of its size against it reads as one 25 x 14 cm object, which matches
no taught view. No geometry of the merged points says where one ends, but the objects
differ in brightness or in height, even within one frame of a camera whose exposure and white
balance drift: :func:`cluster_splits` divides each cluster by each of these
(:func:`split_masks`), keeps each side's connected pieces, and describes each piece as an
object of its own (:func:`~smccli.perception.clusters.describe_points`). The SMC's taught
perception then says whether a piece is the taught object
(:func:`~smccli.execute.matching.match_arm` tries these only where no single cluster, nor
a union of two, is contingent), the mirror image of
:func:`~smccli.perception.clusters.cluster_unions`.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree

from smccli.perception.cloud import heights_above
from smccli.perception.clusters import Cluster, describe_points
from smccli.perception.params import PerceptionParams
from smccli.perception.segment import Segmentation, cluster_labels, segment_frame, standing_clusters
from smccli.world.sensors import CameraFrame, RobotGeometry

TOP_RADIUS = 0.015
"""Radius of the neighbourhood whose highest point is a point's *local top* [m]: a side
face's points then carry their own object's top height (a box's side is 4-7 cm wide),
so two objects of different heights fall apart by it."""
MIN_STEP = 0.003
"""Smallest difference of the two sides' mean local top for a height split [m]: the
depth camera's noise on a flat top is about 1 mm."""
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
    one's) and by each point's local top above ``plane`` (:data:`TOP_RADIUS`: one object
    taller than the other). Chroma (max - min) divided none of the 46 merged white box
    and look-alike clusters of seed 0 usefully (docs/perception.md) and is left out."""
    masks = [otsu_split(colors.max(axis=1).astype(np.float64), MIN_BRIGHTNESS_STEP)]
    if plane is not None:
        h = heights_above(points, plane)
        near = cKDTree(points[:, :2]).query_ball_point(points[:, :2], TOP_RADIUS)
        top = np.array([h[j].max() for j in near])
        masks.append(otsu_split(top * 1000.0, MIN_STEP * 1000.0))  # in mm: 0-255
    return [m for m in masks if m is not None]


def split_parts(
    seg: Segmentation, idx: np.ndarray, plane: np.ndarray | None, params: PerceptionParams
) -> list[np.ndarray]:
    """The pieces ``idx`` (k,) of ``seg`` divides into: each side of each of
    :func:`split_masks`, cut into its connected pieces (DBSCAN with the scene's own
    parameters), those of at least ``min_cluster_points``; no piece twice."""
    out: list[np.ndarray] = []
    seen: set[bytes] = set()
    for mask in split_masks(seg.points[idx], seg.colors[idx], plane):
        for side in (idx[mask], idx[~mask]):
            labels = cluster_labels(seg.points[side], params)
            for k in range(int(labels.max(initial=-1)) + 1):
                part = side[labels == k]
                key = part.tobytes()
                if len(part) >= params.min_cluster_points and key not in seen:
                    seen.add(key)
                    out.append(part)
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
            found.append(describe_points(seg, part, params, base))
    return tuple(sorted(found, key=lambda c: (float(c.centroid[0]), float(c.centroid[1]))))
