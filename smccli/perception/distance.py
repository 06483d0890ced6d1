"""Distances between perceptions, each normalised so that 1 means "clearly different" (eq. 26).

The cluster distance has one implementation, :func:`d_cluster_matrix`, over stacks of
clusters (:class:`ClusterTerms`): a decision point compares every cluster seen with every
child SMC's in one matrix product; :func:`d_cluster` is its 1 x 1 case.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from smccli.perception.clusters import Cluster
from smccli.perception.histogram import d_bhattacharyya
from smccli.perception.params import PerceptionParams

MIN_EXTENT = 1e-3
"""Extents are floored at 1 mm so that log-ratios stay finite [m]."""


def log_extents(extents: np.ndarray) -> np.ndarray:
    """ln of extents (..., 3) [m] floored at :data:`MIN_EXTENT`, same shape."""
    return np.log(np.maximum(np.asarray(extents, dtype=np.float64), MIN_EXTENT))


def d_extents(a: np.ndarray, b: np.ndarray, tolerance: float = 0.0) -> float:
    """Largest log-ratio of (length, width, height), shape (3,) [m]: relative, symmetric.

    |ln(a/b)| treats a 2 cm -> 2.4 cm change like 10 cm -> 12 cm (about 0.18), which is
    what the measurement error of a depth camera looks like (pixels, not millimetres).
    The footprint sides are sorted (length >= width), so yaw does not matter.
    ``tolerance`` [m]: see :func:`_d_extents_matrix`.
    """
    return float(_d_extents_matrix(log_extents(a)[None], log_extents(b)[None], tolerance)[0, 0])


def _d_extents_matrix(a: np.ndarray, b: np.ndarray, tolerance: float) -> np.ndarray:
    """(A, B): :func:`d_extents` of log-extents ``a`` (A, 3) and ``b`` (B, 3), each side's
    difference first shrunk by ``tolerance`` [m] (none below 0): ln((larger - tolerance) /
    smaller) (``PerceptionParams.extent_tolerance``)."""
    diff = np.abs(a[:, None, :] - b[None, :, :])
    if tolerance > 0:
        smaller = np.exp(np.minimum(a[:, None, :], b[None, :, :]))
        diff = np.log(np.maximum(np.exp(diff) - tolerance / smaller, 1.0))
    return diff.max(axis=2)


@dataclass(frozen=True)
class ClusterTerms:
    """What :func:`d_cluster_matrix` compares of N clusters, stacked (some rows may stand
    for no cluster: zeros and NaN there, for the caller to mask)."""

    sqrt_hist: np.ndarray
    """(N, H): square root of each normalised colour histogram."""
    log_extents: np.ndarray
    """(N, 3): :func:`log_extents` of each cluster's extents."""
    brightness: np.ndarray
    """(N,): each relative brightness; NaN where unknown (no table to compare with, a tree
    from before the term)."""

    @cached_property
    def log_brightness(self) -> np.ndarray:
        """(N,): ln of :attr:`brightness` (computed once, and only where the term is on)."""
        return np.log(self.brightness)

    @classmethod
    def of(cls, clusters: Sequence[Cluster | None]) -> ClusterTerms:
        """The terms of ``clusters``; a None row holds zeros and a NaN brightness."""
        seen = [c for c in clusters if c is not None]
        if len(seen) == len(clusters) and seen:  # the context at a decision point
            return cls._of(seen)
        n = len(clusters)
        hist = np.zeros((n, len(seen[0].histogram) if seen else 1))
        ext = np.zeros((n, 3))
        bright = np.full(n, np.nan)
        if seen:
            rows = [i for i, c in enumerate(clusters) if c is not None]
            terms = cls._of(seen)
            hist[rows], ext[rows], bright[rows] = (
                terms.sqrt_hist,
                terms.log_extents,
                terms.brightness,
            )
        return cls(sqrt_hist=hist, log_extents=ext, brightness=bright)

    @classmethod
    def _of(cls, clusters: Sequence[Cluster]) -> ClusterTerms:
        h = np.array([c.histogram for c in clusters], dtype=np.float64)
        return cls(
            sqrt_hist=np.sqrt(h / np.maximum(h.sum(axis=1, keepdims=True), 1e-300)),
            log_extents=log_extents(np.array([c.extents for c in clusters], dtype=np.float64)),
            brightness=np.array([c.brightness for c in clusters], dtype=np.float64),
        )


def d_cluster_matrix(a: ClusterTerms, b: ClusterTerms, params: PerceptionParams) -> np.ndarray:
    """Perception distance of every cluster of ``a`` (A rows) to every one of ``b`` (B rows),
    shape (A, B) (eq. 15 and 26, ML part).

    Sum of the textbook Bhattacharyya distance of the colour histograms
    (:func:`~smccli.perception.histogram.d_bhattacharyya`) over ``hist_scale``, the
    extents' largest log-ratio (:func:`d_extents`) over ``extent_scale`` and, where it is
    on, the relative brightnesses' log-ratio over ``brightness_scale`` (0 where either is
    unknown): each term is 1 when "clearly different"; same objects seen from any pose
    score below T_hP = 0.1. Symmetric, 0 for identical clusters; the location plays no
    part (eq. 15).
    """
    d_h = d_bhattacharyya(a.sqrt_hist @ b.sqrt_hist.T)
    d_e = _d_extents_matrix(a.log_extents, b.log_extents, params.extent_tolerance)
    d = d_h / params.hist_scale + d_e / params.extent_scale
    if params.brightness_scale > 0:
        d_b = np.abs(a.log_brightness[:, None] - b.log_brightness[None, :])
        d = d + np.where(np.isnan(d_b), 0.0, d_b) / params.brightness_scale
    return d


def unmeasured(stored: ClusterTerms, seen: ClusterTerms, params: PerceptionParams) -> np.ndarray:
    """(A, B) bool: a term of a ``stored`` cluster that the ``seen`` one could not measure
    (its brightness: a box seen from right above, its sides out of sight)."""
    if params.brightness_scale <= 0:
        return np.zeros((len(stored.brightness), len(seen.brightness)), dtype=bool)
    return ~np.isnan(stored.brightness)[:, None] & np.isnan(seen.brightness)[None, :]


def d_cluster(a: Cluster, b: Cluster, params: PerceptionParams | None = None) -> float:
    """Perception distance of two object clusters: :func:`d_cluster_matrix` of one each."""
    params = params or PerceptionParams()
    return float(d_cluster_matrix(ClusterTerms._of([a]), ClusterTerms._of([b]), params)[0, 0])


def d_scalar(a: float, b: float, scale: float) -> float:
    """|a - b| / scale for SI scalars such as a weight (eq. 9); ``scale`` in the same unit
    as a and b is the difference that counts as "clearly different"."""
    if scale <= 0:
        raise ValueError(f"d_scalar: scale must be > 0, got {scale}")
    return abs(float(a) - float(b)) / scale
