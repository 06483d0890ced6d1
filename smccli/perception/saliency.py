"""Which cluster is salient for a fragment (rules (d)-(e), eq. 21-25)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from smccli.perception.clusters import Cluster

DEFAULT_EPSILON = 0.05
"""Default epsilon of the object clusters [m], horizontal: a grasp centred on an object
within a few cm, a placement on top of one, and demo noise (tremor, operator offset) stay
well inside; the nearest other object in the built-in scenes is >= 10 cm away."""


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
