"""Distances between perceptions, each normalised so that 1 means "clearly different" (eq. 26)."""

from __future__ import annotations

import math

import numpy as np

from smccli.perception.clusters import Cluster
from smccli.perception.histogram import d_histogram
from smccli.perception.params import PerceptionParams

MIN_EXTENT = 1e-3
"""Extents are floored at 1 mm so that log-ratios stay finite [m]."""


def d_extents(a: np.ndarray, b: np.ndarray) -> float:
    """Largest log-ratio of (length, width, height), shape (3,) [m]: relative, symmetric.

    |ln(a/b)| treats a 2 cm -> 2.4 cm change like 10 cm -> 12 cm (about 0.18), which is
    what the measurement error of a depth camera looks like (pixels, not millimetres).
    The footprint sides are sorted (length >= width), so yaw does not matter.
    """
    ea = np.maximum(np.asarray(a, dtype=np.float64), MIN_EXTENT)
    eb = np.maximum(np.asarray(b, dtype=np.float64), MIN_EXTENT)
    return float(np.max(np.abs(np.log(ea / eb))))


def d_brightness(a: float, b: float) -> float:
    """|ln(a/b)| of two relative brightnesses (:mod:`smccli.perception.brightness`); 0 when
    either is NaN (no table to compare with, or a tree from before the term)."""
    if math.isnan(a) or math.isnan(b):
        return 0.0
    return abs(math.log(a / b))


def d_cluster(a: Cluster, b: Cluster, params: PerceptionParams | None = None) -> float:
    """Perception distance of two object clusters (eq. 15 and 26, ML part).

    Sum of the textbook Bhattacharyya distance of the colour histograms over
    ``hist_scale``, the extents' log-ratio over ``extent_scale`` and, where it is on, the
    relative brightnesses' log-ratio over ``brightness_scale``: each term is 1 when "clearly
    different"; same objects seen from any pose score below T_hP = 0.1.
    Symmetric, 0 for identical clusters; the location plays no part (eq. 15).
    """
    params = params or PerceptionParams()
    d_h = d_histogram(a.histogram, b.histogram) / params.hist_scale
    d_e = d_extents(a.extents, b.extents) / params.extent_scale
    if params.brightness_scale <= 0:
        return float(d_h + d_e)
    d_b = d_brightness(a.brightness, b.brightness) / params.brightness_scale
    return float(d_h + d_e + d_b)


def d_scalar(a: float, b: float, scale: float) -> float:
    """|a - b| / scale for SI scalars such as a weight (eq. 9); ``scale`` in the same unit
    as a and b is the difference that counts as "clearly different"."""
    if scale <= 0:
        raise ValueError(f"d_scalar: scale must be > 0, got {scale}")
    return abs(float(a) - float(b)) / scale
