"""Perception saliency for the depth camera (section 3.3): object clusters and their distances.

Pipeline (:func:`clusters_from_frame`): depth -> world points -> workspace crop ->
self-filter -> table plane removal (RANSAC) -> DBSCAN -> per cluster a colour histogram,
an upright oriented box (centroid, yaw, extents). :func:`d_cluster` compares two clusters
(1 = clearly different, T_hP = 0.1 separates same from different);
:func:`salient_cluster` picks the cluster at the POI (eq. 20-22).
"""

from smccli.perception.cloud import cloud_from_frame
from smccli.perception.clusters import (
    Cluster,
    cluster_from_dict,
    cluster_to_dict,
    clusters_from_frame,
)
from smccli.perception.distance import d_cluster, d_extents, d_scalar
from smccli.perception.histogram import d_histogram, hsv_histogram
from smccli.perception.params import PerceptionParams
from smccli.perception.saliency import DEFAULT_EPSILON, salient_cluster, scale_reading

__all__ = [
    "DEFAULT_EPSILON",
    "Cluster",
    "PerceptionParams",
    "cloud_from_frame",
    "cluster_from_dict",
    "cluster_to_dict",
    "clusters_from_frame",
    "d_cluster",
    "d_extents",
    "d_histogram",
    "d_scalar",
    "hsv_histogram",
    "salient_cluster",
    "scale_reading",
]
