"""Which cluster is salient for a fragment (rules (d)-(e), eq. 21-25), and the scale's
reading at a decision point (SI, always salient)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from smccli.perception.clusters import Cluster

DEFAULT_EPSILON = 0.08
"""Saliency radius of object clusters (eq. 21) [m], horizontal: a grasp centred on an object
within a few cm, a placement on top of one, and demo noise (tremor, operator offset) stay
well inside; the nearest other object in the built-in scenes is >= 10 cm away. The one
source of ``SmcParams.epsilon``'s default (:mod:`smccli.learn.params`)."""


def salient_cluster(
    clusters: Sequence[Cluster], poi_xyz: np.ndarray, epsilon: float = DEFAULT_EPSILON
) -> int | None:
    """Index of the cluster nearest to the POI if within ``epsilon`` [m], else None (eq. 21-22).

    Distance d_X is horizontal (x-y) between the cluster's centroid and ``poi_xyz`` (shape
    (3,) or more, [m]): at the end of a grasp from above the POI is at the object's
    height, but at the end of a placement on top of an object it is above that object by
    the held object's height, so a 3-D distance would need a much larger epsilon and would
    then pick up neighbours. Ties go to the lower index (clusters are sorted).
    """
    if len(clusters) == 0:
        return None
    poi = np.asarray(poi_xyz, dtype=np.float64)[:2]
    d = np.array([np.hypot(*(c.centroid[:2] - poi)) for c in clusters])
    k = int(np.argmin(d))
    return k if d[k] < epsilon else None


def scale_reading(t: np.ndarray, kg: np.ndarray, t_decision: float, window: float) -> float:
    """The scale at a decision point [kg]: the median of the readings ``kg`` (W,) at times
    ``t`` (W,) [s] in the ``window`` [s] that ends at ``t_decision`` (the nearest reading
    when none falls inside). Compile and replay both read it so, at the same instant: where
    the previous action has settled, before the next one starts."""
    t, kg = np.asarray(t, dtype=float), np.asarray(kg, dtype=float)
    if len(t) == 0:
        raise ValueError("scale_reading: no readings")
    inside = (t >= t_decision - window - 1e-9) & (t <= t_decision + 1e-9)
    if not inside.any():
        return float(kg[int(np.argmin(np.abs(t - t_decision)))])
    return float(np.median(kg[inside]))
