"""Distances and contingency relations (paper 3.3-3.5, eq. 26, 29, 31, 36) and SMC merging.

D_P sums per-sensor distances, each normalised so that 1 means "clearly different":
clusters by :func:`smccli.perception.d_cluster`, the scale by |dw| / ``weight_scale``.
Perception sets of different kinds (a cluster on one side only) are never contingent.

D_A is physical, in metres: the distance between the two goals (position, plus
``yaw_scale`` metres per radian of yaw) plus the DMPs' shape distance (RMS distance of the
canonical, yaw-aligned rollouts; see docs/dmp.md). The paper's T_hA = 0.02 then reads
"goals and paths within 2 cm". Actions with different gripper events or goal frames are
never contingent (D_A = inf).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from smccli import dmp as dmp_mod
from smccli.params import SmcParams
from smccli.perception import Cluster, d_cluster
from smccli.smc import Action, SalientPerceptions, Smc, wrap_angle

INF = math.inf


def d_p(a: SalientPerceptions, b: SalientPerceptions, params: SmcParams) -> float:
    """Inter-perception distance D_P between two salient sets (eq. 26)."""
    total = 0.0
    if (a.cluster is None) != (b.cluster is None):
        return INF
    if a.cluster is not None and b.cluster is not None:
        total += d_cluster(a.cluster, b.cluster, params.perception)
    if (a.weight is None) != (b.weight is None):
        return INF
    if a.weight is not None and b.weight is not None:
        total += abs(a.weight - b.weight) / params.weight_scale
    return total


def d_a(a: Action, b: Action, params: SmcParams) -> float:
    """Inter-action distance D_A (eq. 29) [m]; inf for different gripper events or frames."""
    if a.event != b.event or a.goal_frame != b.goal_frame:
        return INF
    goal = float(np.linalg.norm(a.goal[:3] - b.goal[:3]))
    goal += params.yaw_scale * abs(wrap_angle(float(a.goal[3] - b.goal[3]), math.pi))
    return goal + dmp_mod.shape_distance(a.dmp, b.dmp)


def c_f(a: Smc, b: Smc, params: SmcParams) -> bool:
    """Fragment contingency C_F (eq. 31)."""
    return (
        d_a(a.action, b.action, params) < params.t_ha
        and d_p(a.perception, b.perception, params) < params.t_hp
    )


@dataclass(frozen=True, slots=True)
class Match:
    """How well the current context matches one stored SMC (eq. 36, 39)."""

    d_p: float
    """D_P between the context's best-matching salient perceptions and the SMC's."""
    cluster_index: int | None
    """Index of the context cluster chosen as the SMC's localized perception (eq. 39)."""
    contingent: bool
    """C_Now: d_p < T_hP (eq. 36)."""


def match_context(
    stored: SalientPerceptions, clusters: Sequence[Cluster], weight: float | None, params: SmcParams
) -> Match:
    """C_Now of a context (clusters seen now, scale reading now) against a stored SMC.

    The context's salient localized perception is the cluster nearest the stored one in
    perception (eq. 39): at a decision point the POI has not moved yet, so nearness to it
    cannot choose.
    """
    total = 0.0
    index: int | None = None
    if stored.cluster is not None:
        if not clusters:
            return Match(d_p=INF, cluster_index=None, contingent=False)
        dists = [d_cluster(c, stored.cluster, params.perception) for c in clusters]
        index = int(np.argmin(dists))
        total += dists[index]
    if stored.weight is not None:
        if weight is None:
            return Match(d_p=INF, cluster_index=index, contingent=False)
        total += abs(weight - stored.weight) / params.weight_scale
    return Match(d_p=total, cluster_index=index, contingent=total < params.t_hp)


def _mean_cluster(a: Cluster, b: Cluster, wa: float, wb: float) -> Cluster:
    hist = (wa * a.histogram + wb * b.histogram) / (wa + wb)
    hist = hist / max(float(hist.sum()), 1e-12)
    period = a.yaw_period if a.yaw_period > 0 else 2 * math.pi
    yaw = a.yaw + wb / (wa + wb) * wrap_angle(b.yaw - a.yaw, period)
    return dataclasses.replace(
        a,
        histogram=hist,
        extents=(wa * a.extents + wb * b.extents) / (wa + wb),
        centroid=(wa * a.centroid + wb * b.centroid) / (wa + wb),
        yaw=float(yaw),
    )


def merge(a: Smc, b: Smc, support_a: int, support_b: int = 1) -> Smc:
    """Merge two contingent SMCs: the support-weighted mean of their parameters (3.8)."""
    wa, wb = float(support_a), float(support_b)
    pa, pb = a.perception, b.perception
    cluster = None
    if pa.cluster is not None and pb.cluster is not None:
        cluster = _mean_cluster(pa.cluster, pb.cluster, wa, wb)
    weight = None
    if pa.weight is not None and pb.weight is not None:
        weight = (wa * pa.weight + wb * pb.weight) / (wa + wb)
    aa, ab = a.action, b.action
    goal = (wa * aa.goal + wb * ab.goal) / (wa + wb)
    goal[3] = aa.goal[3] + wb / (wa + wb) * wrap_angle(float(ab.goal[3] - aa.goal[3]), math.pi)
    action = Action(
        dmp=dmp_mod.merge([aa.dmp, ab.dmp], [wa, wb]),
        goal_frame=aa.goal_frame,
        goal=goal,
        gripper_start=(wa * aa.gripper_start + wb * ab.gripper_start) / (wa + wb),
        gripper_end=(wa * aa.gripper_end + wb * ab.gripper_end) / (wa + wb),
        gripper_phase=(wa * aa.gripper_phase + wb * ab.gripper_phase) / (wa + wb),
    )
    return Smc(perception=SalientPerceptions(cluster=cluster, weight=weight), action=action)
