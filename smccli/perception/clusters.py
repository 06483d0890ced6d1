"""Object clusters (ML perception, section 3.3): one RGB-D frame -> the objects on the table."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import open3d as o3d

from smccli.perception.cloud import object_points, plane_distance
from smccli.perception.histogram import hsv_histogram
from smccli.perception.params import PerceptionParams
from smccli.sensors import CameraFrame, RobotGeometry


@dataclass(frozen=True, slots=True)
class Cluster:
    """One object seen on the table: a localized perception (value = look, location = pose)."""

    centroid: np.ndarray
    """Centre of the cluster's upright oriented box, shape (3,) [m], world frame: the
    footprint rectangle's centre in x-y, halfway between the table and the top in z (the
    mean of the visible points would lean towards the camera)."""
    yaw: float
    """Yaw of the footprint's longest horizontal axis about world z, in (-pi/2, pi/2]
    [rad]; 0 for a round footprint. Meaningful modulo ``yaw_period``."""
    yaw_period: float
    """Symmetry of the footprint [rad]: pi elongated, pi/2 square, 0 round (yaw undefined)."""
    extents: np.ndarray
    """(length, width, height), shape (3,) [m]: footprint sides (length >= width) and the
    top's height above the table plane."""
    histogram: np.ndarray
    """Colour histogram, shape (hue_bins * sat_bins + val_bins,), sums to 1
    (see :mod:`smccli.perception.histogram`)."""
    n_points: int
    """Number of points in the cluster (after the optional voxel downsampling); with it off,
    the object's area in the image [px]."""

    @property
    def location(self) -> np.ndarray:
        """``[x, y, z, yaw]``, shape (4,) [m, m, m, rad]."""
        return np.r_[self.centroid, self.yaw]


def _wrap_half_pi(a: float) -> float:
    """Wrap an axis direction (defined modulo pi) into (-pi/2, pi/2]."""
    a = (a + np.pi / 2) % np.pi - np.pi / 2  # [-pi/2, pi/2)
    return np.pi / 2 if a <= -np.pi / 2 + 1e-12 else float(a)


def describe_cluster(
    points: np.ndarray, colors: np.ndarray, plane: np.ndarray | None, params: PerceptionParams
) -> Cluster:
    """Location, extents, symmetry and histogram of one cluster's points (n, 3) [m]."""
    # Height above the table: signed distance to the table plane.
    if plane is not None:
        heights = plane_distance(points, plane)
    else:
        heights = points[:, 2] - points[:, 2].min()
    height = float(heights.max())
    xy = points[:, :2].astype(np.float64)
    # The camera sees the top and the near sides only, so the visible footprint of e.g. a
    # pyramid is a triangle. The top (a box's or cylinder's top face, a pyramid's apex) is
    # seen whole and lies over the footprint's centre: take the centre of the top layer,
    # and complete the footprint by point symmetry about it (exact for boxes, cylinders,
    # pyramids and cones, the objects of the built-in scenes).
    top = xy[heights > height - params.top_band]
    (cx, cy), _, _ = cv2.minAreaRect(top.astype(np.float32))
    center = np.array([cx, cy])
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
        yaw = _wrap_half_pi(float(np.arctan2(long_edge[1], long_edge[0])))
    else:  # square: report a side's direction in [-pi/4, pi/4), the period is pi/2
        a = float(np.arctan2(long_edge[1], long_edge[0]))
        yaw = float((a + np.pi / 4) % (np.pi / 2) - np.pi / 4)
    return Cluster(
        centroid=np.array([cx, cy, base_z + height / 2]),
        yaw=yaw,
        yaw_period=float(yaw_period),
        extents=np.array([length, width, height]),
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


def clusters_from_frame(
    frame: CameraFrame, robot: RobotGeometry | None, params: PerceptionParams | None = None
) -> tuple[Cluster, ...]:
    """The object clusters in one RGB-D frame (ML perception, eq. 14).

    depth -> world points -> crop -> self-filter (``robot``'s spheres) -> table plane
    removal (RANSAC) -> DBSCAN -> per cluster: histogram, box centre, yaw, extents.
    Sorted by centroid x, then y. Uses only the images and the robot's own geometry.
    """
    params = params or PerceptionParams()
    points, colors, plane = object_points(frame, robot, params)
    labels = cluster_labels(points, params)
    found = []
    for k in range(int(labels.max(initial=-1)) + 1):
        idx = np.flatnonzero(labels == k)
        if len(idx) < params.min_cluster_points:
            continue
        found.append(describe_cluster(points[idx], colors[idx], plane, params))
    found.sort(key=lambda c: (float(c.centroid[0]), float(c.centroid[1])))
    return tuple(found)


def cluster_to_dict(c: Cluster) -> dict:
    """JSON-ready form of a cluster (lists of floats), for tree files and logs."""
    return {
        "centroid": [float(v) for v in c.centroid],
        "yaw": float(c.yaw),
        "yaw_period": float(c.yaw_period),
        "extents": [float(v) for v in c.extents],
        "histogram": [float(v) for v in c.histogram],
        "n_points": int(c.n_points),
    }


def cluster_from_dict(d: dict) -> Cluster:
    """Inverse of :func:`cluster_to_dict`."""
    return Cluster(
        centroid=np.asarray(d["centroid"], dtype=np.float64),
        yaw=float(d["yaw"]),
        yaw_period=float(d["yaw_period"]),
        extents=np.asarray(d["extents"], dtype=np.float64),
        histogram=np.asarray(d["histogram"], dtype=np.float64),
        n_points=int(d["n_points"]),
    )
