"""Perception saliency for the depth camera (section 3.3): object clusters and their distances.

Pipeline (:func:`clusters_from_frame`): depth -> world points -> workspace crop ->
self-filter -> table plane removal (RANSAC) -> DBSCAN -> parts joined -> per cluster a
colour histogram, an upright oriented box (centroid, yaw, extents); :func:`cluster_unions`
describes neighbouring clusters as one (an object seen in pieces), :func:`cluster_splits`
one cluster's pieces as objects (objects touching). :func:`d_cluster`
compares two clusters (1 = clearly different, T_hP = 0.1 separates same from different);
:func:`salient_cluster` picks the cluster at the POI (eq. 20-22).

The mobile half (paper 4.2): a 2-D lidar scan (SL, :mod:`~smccli.perception.scan`) with
:func:`align_scans`, :func:`scan_distance` and the goal mapping of eq. 38-39, and the room's
colour histogram (SI, :mod:`~smccli.perception.room`).
"""

import open3d as o3d

from smccli.perception.cloud import cloud_from_frame
from smccli.perception.clusters import (
    Cluster,
    cluster_from_dict,
    cluster_to_dict,
    cluster_unions,
    clusters_from_frame,
)
from smccli.perception.distance import d_cluster, d_extents, d_scalar
from smccli.perception.histogram import d_histogram, hsv_histogram
from smccli.perception.params import PerceptionParams
from smccli.perception.room import d_room, room_histogram
from smccli.perception.saliency import DEFAULT_EPSILON, salient_cluster, scale_reading
from smccli.perception.scan import (
    Scan2D,
    ScanAlignment,
    ScanParams,
    align_scans,
    scan_distance,
    scan_from_dict,
    scan_to_dict,
)
from smccli.perception.splits import cluster_splits, cluster_windows

# open3d's parallel loops (ICP's normal equations, RANSAC, DBSCAN) reduce in thread order:
# their last bits vary from run to run, enough to flip a decision near a threshold. One
# thread gives the same bits every time (campaigns run a trial per core anyway).
# OMP_NUM_THREADS does not reach open3d's own OpenMP; this does.
o3d.utility.set_max_threads(1)

__all__ = [
    "DEFAULT_EPSILON",
    "Cluster",
    "PerceptionParams",
    "Scan2D",
    "ScanAlignment",
    "ScanParams",
    "align_scans",
    "cloud_from_frame",
    "cluster_from_dict",
    "cluster_splits",
    "cluster_windows",
    "cluster_to_dict",
    "cluster_unions",
    "clusters_from_frame",
    "d_cluster",
    "d_extents",
    "d_histogram",
    "d_room",
    "d_scalar",
    "hsv_histogram",
    "room_histogram",
    "salient_cluster",
    "scale_reading",
    "scan_distance",
    "scan_from_dict",
    "scan_to_dict",
]
