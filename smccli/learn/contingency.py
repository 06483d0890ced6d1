"""Distances and contingency relations (paper 3.3-3.5, eq. 26, 29, 31, 36) and SMC merging.

D_P sums per-sensor distances, each normalised so that 1 means "clearly different":
clusters by :func:`smccli.perception.d_cluster`, the scale by |dw| / ``weight_scale``, a
room's colours by :func:`smccli.perception.room.d_room`, a lidar scan by the trimmed
chamfer distance once aligned by ICP (:mod:`smccli.perception.scan`).
Perception sets of different kinds (a cluster on one side only) are never contingent.

D_A is physical, in metres: the distance between the two goals in the salient object's
frame (position, plus ``yaw_scale`` metres per radian of yaw; for a base, in the frame of
the salient scan, the other scan's goal carried over by the ICP transform between the two
scans) plus the RMS distance of the two approaches (the paths' last ``approach_length``
metres, relative to the goal), both
taken at the object's symmetric equivalent that fits best. The paper's T_hA = 0.02 then
reads "the same goal relative to the object, reached the same way, within 2 cm", whatever
the layout the demonstrations started from (docs/choices.md). Actions with different
gripper events or goal frames are never contingent (D_A = inf).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from smccli.learn import dmp as dmp_mod
from smccli.learn.params import SmcParams
from smccli.learn.smc import (
    TWO_PI,
    Action,
    SalientPerceptions,
    Smc,
    common_symmetry,
    symmetry_rotations,
)
from smccli.perception import Cluster, d_cluster
from smccli.perception.distance import ClusterTerms, d_cluster_matrix, unmeasured
from smccli.perception.room import d_room
from smccli.perception.scan import Memo, align_scans, chamfer, scan_key
from smccli.world.geometry import compose, rotate_z, se2_pose, wrap, wrap_yaw

INF = math.inf
_TRANSFORMS: Memo[np.ndarray | None] = Memo(256)
""":func:`scan_transform`'s last answers, by the two scans and the scan parameters: a run
asks again, every trial, for the same two taught scans' alignment (whether two siblings
are equivalent), each a full ICP search of about 20 ms."""


def scan_transform(
    a: SalientPerceptions, b: SalientPerceptions, params: SmcParams
) -> np.ndarray | None:
    """Where ``b``'s lidar sat in ``a``'s lidar frame, by ICP of their scans: SE(2) (3, 3);
    None unless both hold a scan. The same scans give the same answer (a copy, remembered:
    ICP is deterministic)."""
    sa, sb = a.scan, b.scan
    if sa is None or sb is None:
        return None

    def align() -> np.ndarray | None:
        try:
            return align_scans(sa, sb, params.scan).T_target_source
        except ValueError:  # too few returns to align: no common frame
            return None

    T = _TRANSFORMS.get((scan_key(sa), scan_key(sb), params.scan), align)
    return None if T is None else T.copy()


def d_p(
    a: SalientPerceptions,
    b: SalientPerceptions,
    params: SmcParams,
    T_ab: np.ndarray | None = None,
) -> float:
    """Inter-perception distance D_P between two salient sets (eq. 26). ``T_ab``: the scans'
    alignment (:func:`scan_transform`) when the caller has it."""
    total = 0.0
    if (a.cluster is None) != (b.cluster is None):
        return INF
    if (a.room is None) != (b.room is None) or (a.scan is None) != (b.scan is None):
        return INF
    if a.room is not None and b.room is not None:
        total += d_room(a.room, b.room, params.perception)
    if a.scan is not None and b.scan is not None:
        T_ab = scan_transform(a, b, params) if T_ab is None else T_ab
        if T_ab is None:
            return INF
        total += chamfer(a.scan, b.scan, T_ab, params.scan) / params.scan.distance_scale
    if a.cluster is not None and b.cluster is not None:
        total += d_cluster(a.cluster, b.cluster, params.perception)
    if (a.weight is None) != (b.weight is None):
        return INF
    if a.weight is not None and b.weight is not None:
        total += abs(a.weight - b.weight) / params.weight_scale
    return total


@dataclass(frozen=True, slots=True)
class Alignment:
    """How two goals compare once the object's symmetry is taken out (part of eq. 29)."""

    goal: float
    """Goal distance [m]: position + ``yaw_scale`` per radian of yaw (modulo the gripper's pi
    unless the object has no symmetry)."""
    approach: float
    """RMS distance of the two approaches [m] (0 when either has none)."""
    rotation: float
    """The rotation of ``b``'s object frame [rad] that gives the least total."""

    @property
    def total(self) -> float:
        return self.goal + self.approach


def align(a: Action, b: Action, params: SmcParams) -> Alignment:
    """Compare ``b`` to ``a`` over the rotations that map their (common) object symmetry
    onto itself, and keep the best: a square cube grasped at +44 degrees and at -44 degrees
    is the same grasp, seen from a frame that turned by pi/2."""
    symmetry = common_symmetry(a.symmetry, b.symmetry)
    # The parallel gripper's pi is free, except around an object that has no symmetry:
    # there the wrist's pi would put the object's other side in the hand.
    yaw_period = TWO_PI if symmetry >= TWO_PI - 1e-6 else math.pi
    n = min(len(a.approach), len(b.approach))
    best: Alignment | None = None
    for theta in symmetry_rotations(symmetry):
        pos = rotate_z(b.goal[:3], theta)
        goal = float(np.linalg.norm(a.goal[:3] - pos))
        dyaw = wrap(float(a.goal[3] - b.goal[3] - theta), yaw_period)
        goal += params.yaw_scale * abs(dyaw)
        approach = 0.0
        if n:
            gap = a.approach[:n] - rotate_z(b.approach[:n], theta)
            approach = float(np.sqrt(np.mean(np.sum(gap**2, axis=1))))
        if best is None or goal + approach < best.total - 1e-12:
            best = Alignment(goal=goal, approach=approach, rotation=float(theta))
    assert best is not None
    return best


def goal_in_a(b: Action, T_ab: np.ndarray) -> np.ndarray:
    """``b``'s scan-frame goal [dx, dy, 0, dyaw] carried into ``a``'s scan frame by
    ``T_ab`` (b's lidar in a's lidar frame)."""
    x, y, yaw = wrap_yaw(compose(se2_pose(T_ab), b.goal[[0, 1, 3]]))
    return np.array([x, y, 0.0, yaw])


def d_a(a: Action, b: Action, params: SmcParams, T_ab: np.ndarray | None = None) -> float:
    """Inter-action distance D_A (eq. 29) [m]; inf for different gripper events or frames.

    The goal relative to the salient perception and the approach to it, compared over the
    object's symmetric equivalents (:func:`align`); where the action started and how it
    travelled there (which follow from the layout, not from the action) do not count.
    Goals in scan frames are compared in ``a``'s, ``b``'s carried over by ``T_ab`` (the
    scans' alignment, :func:`scan_transform`; inf without one).
    """
    if a.event != b.event or a.goal_frame != b.goal_frame:
        return INF
    if a.goal_frame == "scan":
        if T_ab is None:
            return INF
        return _pose_gap(a.goal, goal_in_a(b, T_ab), params)
    return align(a, b, params).total


def _pose_gap(a: np.ndarray, b: np.ndarray, params: SmcParams) -> float:
    """Distance of two goals [x, y, z, yaw] without symmetry: position + yaw_scale * |dyaw| [m]."""
    return float(np.linalg.norm(a[:3] - b[:3])) + params.yaw_scale * abs(wrap(float(a[3] - b[3])))


def goal_gap(a: Smc, b: Smc, params: SmcParams) -> float:
    """How far apart two SMCs' goals are relative to their salient perceptions [m] (the goal
    part of D_A, approaches left out); inf when they cannot be compared."""
    pa, pb = a.action, b.action
    if pa.event != pb.event or pa.goal_frame != pb.goal_frame:
        return INF
    if pa.goal_frame == "scan":
        T_ab = scan_transform(a.perception, b.perception, params)
        return INF if T_ab is None else _pose_gap(pa.goal, goal_in_a(pb, T_ab), params)
    if (
        pa.goal_frame == "world"
        and pa.symmetry >= TWO_PI - 1e-6
        and pa.held_symmetry >= TWO_PI - 1e-6
    ):
        return _pose_gap(pa.goal, pb.goal, params)  # a base: no gripper's half turn
    return align(pa, pb, params).goal


def c_f(a: Smc, b: Smc, params: SmcParams) -> bool:
    """Fragment contingency C_F (eq. 31)."""
    T_ab = scan_transform(a.perception, b.perception, params)
    return (
        d_a(a.action, b.action, params, T_ab) < params.t_ha
        and d_p(a.perception, b.perception, params, T_ab) < params.t_hp
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


def ranked(d: np.ndarray, unmeasured: np.ndarray, t_hp: float) -> np.ndarray:
    """The order in which clusters match an SMC, from their D_P ``d`` (..., C): first the
    contingent ones (D_P < ``t_hp``) whose every term was measured, then the contingent
    ones ``unmeasured`` (bool, same shape: a term the SMC has that this view could not
    measure, e.g. the brightness of a box seen from right above, its sides out of sight),
    then the rest; by D_P within each. Else a grey bar right under the camera matches a
    white box's SMC better than the white box. The D_P itself is unchanged."""
    tier = np.where(d < t_hp, np.where(unmeasured, 1.0, 0.0), 2.0)
    return tier * RANK_TIER + d


RANK_TIER = 1e6
"""Larger than any finite D_P: :func:`ranked` orders by tier, then by D_P."""


@dataclass(frozen=True, slots=True)
class StoredStack:
    """The salient perceptions of E stored SMCs, stacked to match a context against all of
    them at once (:func:`match_stack`)."""

    clusters: ClusterTerms
    """E rows: each SMC's localized (cluster) perception (zeros where it has none)."""
    has_cluster: np.ndarray
    """(E,) bool: the SMC has a localized (cluster) perception."""
    has_weight: np.ndarray
    """(E,) bool: the SMC has a scale reading."""
    weight: np.ndarray
    """(E,): stored weight [kg] (0 without)."""
    rows: np.ndarray
    """(E,) int: 0, 1, ..., E - 1 (to pick each row's matched cluster)."""
    every_cluster: bool
    """Every SMC has a cluster (nothing to mask)."""

    @classmethod
    def build(cls, stored: Sequence[SalientPerceptions]) -> StoredStack:
        weights = [s.weight for s in stored]
        has_cluster = np.array([s.cluster is not None for s in stored], dtype=bool)
        return cls(
            clusters=ClusterTerms.of([s.cluster for s in stored]),
            has_cluster=has_cluster,
            has_weight=np.array([w is not None for w in weights], dtype=bool),
            weight=np.array([0.0 if w is None else float(w) for w in weights]),
            rows=np.arange(len(stored)),
            every_cluster=bool(has_cluster.all()),
        )


def match_stack(
    stack: StoredStack, clusters: Sequence[Cluster], weight: float | None, params: SmcParams
) -> tuple[np.ndarray, np.ndarray]:
    """C_Now of a context (clusters seen now, scale reading now) against every stacked SMC
    (eq. 36, 39): D_P (E,) and the index (E,) int of the context cluster taken as each
    SMC's localized perception, -1 when the SMC has none; inf where the context lacks a
    reading the SMC has.

    The context's salient localized perception is the cluster nearest the stored one in
    perception, in :func:`ranked` order (eq. 39): at a decision point the POI has not
    moved yet, so nearness to it cannot choose.
    """
    n = len(stack.rows)
    if not clusters or not stack.has_cluster.any():
        d = np.where(stack.has_cluster, np.inf, 0.0)
        idx = np.full(n, -1, dtype=np.int64)
    else:
        pp = params.perception
        seen = ClusterTerms.of(clusters)
        dc = d_cluster_matrix(stack.clusters, seen, pp)  # (E, C)
        rank = dc
        if pp.brightness_scale > 0:
            rank = ranked(dc, unmeasured(stack.clusters, seen, pp), params.t_hp)
        idx = np.argmin(rank, axis=1)
        d = dc[stack.rows, idx]
        if not stack.every_cluster:
            d = np.where(stack.has_cluster, d, 0.0)
            idx = np.where(stack.has_cluster, idx, -1)
    if stack.has_weight.any():
        if weight is None:
            d = np.where(stack.has_weight, np.inf, d)
        else:
            d = d + np.where(
                stack.has_weight, np.abs(weight - stack.weight) / params.weight_scale, 0.0
            )
    return d, idx


def match_context(
    stored: SalientPerceptions, clusters: Sequence[Cluster], weight: float | None, params: SmcParams
) -> Match:
    """C_Now of a context against one stored SMC: :func:`match_stack` of one."""
    d, idx = match_stack(StoredStack.build([stored]), clusters, weight, params)
    index = None if idx[0] < 0 else int(idx[0])
    return Match(d_p=float(d[0]), cluster_index=index, contingent=bool(d[0] < params.t_hp))


def _mean_cluster(a: Cluster, b: Cluster, wa: float, wb: float) -> Cluster:
    hist = (wa * a.histogram + wb * b.histogram) / (wa + wb)
    hist = hist / max(float(hist.sum()), 1e-12)
    period = a.yaw_period if a.yaw_period > 0 else 2 * math.pi
    yaw = a.yaw + wb / (wa + wb) * wrap(b.yaw - a.yaw, period)
    # The geometric mean of the relative brightnesses (the term is a log-ratio); a tree
    # from before the term keeps the one that has it.
    if math.isnan(a.brightness) or math.isnan(b.brightness):
        brightness = b.brightness if math.isnan(a.brightness) else a.brightness
    else:
        log_b = (wa * math.log(a.brightness) + wb * math.log(b.brightness)) / (wa + wb)
        brightness = math.exp(log_b)
    return dataclasses.replace(
        a,
        histogram=hist,
        brightness=brightness,
        extents=(wa * a.extents + wb * b.extents) / (wa + wb),
        centroid=(wa * a.centroid + wb * b.centroid) / (wa + wb),
        yaw=float(yaw),
    )


def merge(
    a: Smc, b: Smc, support_a: int, support_b: int = 1, params: SmcParams | None = None
) -> Smc:
    """Merge two contingent SMCs: the support-weighted mean of their parameters (3.8).

    ``b``'s goal and approach are first turned into ``a``'s symmetric equivalent
    (:func:`align`), so that the mean is taken between like and like.
    """
    wa, wb = float(support_a), float(support_b)
    pa, pb = a.perception, b.perception
    cluster = None
    if pa.cluster is not None and pb.cluster is not None:
        cluster = _mean_cluster(pa.cluster, pb.cluster, wa, wb)
    weight = None
    if pa.weight is not None and pb.weight is not None:
        weight = (wa * pa.weight + wb * pb.weight) / (wa + wb)
    room = None
    if pa.room is not None and pb.room is not None:
        room = (wa * pa.room + wb * pb.room) / (wa + wb)
        room = room / max(float(room.sum()), 1e-12)
    aa, ab = a.action, b.action
    params = params or SmcParams()
    if aa.goal_frame == "scan":
        # b's goal in a's scan frame; a's scan stays the SMC's (a point cloud has no mean).
        T_ab = scan_transform(pa, pb, params)
        goal_b, theta = (ab.goal if T_ab is None else goal_in_a(ab, T_ab)), 0.0
    else:
        theta = align(aa, ab, params).rotation
        goal_b = np.r_[rotate_z(ab.goal[:3], theta), ab.goal[3] + theta]
    symmetry = common_symmetry(aa.symmetry, ab.symmetry)
    yaw_period = TWO_PI if symmetry >= TWO_PI - 1e-6 else math.pi
    goal = (wa * aa.goal + wb * goal_b) / (wa + wb)
    goal[3] = wrap(aa.goal[3] + wb / (wa + wb) * wrap(float(goal_b[3] - aa.goal[3]), yaw_period))
    n = min(len(aa.approach), len(ab.approach))
    approach = (wa * aa.approach[:n] + wb * rotate_z(ab.approach[:n], theta)) / (wa + wb)
    action = Action(
        dmp=dmp_mod.merge([aa.dmp, ab.dmp], [wa, wb]),
        goal_frame=aa.goal_frame,
        goal=goal,
        gripper_start=(wa * aa.gripper_start + wb * ab.gripper_start) / (wa + wb),
        gripper_end=(wa * aa.gripper_end + wb * ab.gripper_end) / (wa + wb),
        gripper_phase=(wa * aa.gripper_phase + wb * ab.gripper_phase) / (wa + wb),
        symmetry=symmetry,
        approach=approach.reshape(-1, 3),
        held_symmetry=max(aa.held_symmetry, ab.held_symmetry),
        poi=aa.poi,
        hand_yaw=aa.hand_yaw,
    )
    if aa.base_dmp is not None and ab.base_dmp is not None:
        # A mobile manipulator's base path: merged as the hand's, its goal turned alike.
        assert aa.base_goal is not None and ab.base_goal is not None
        base_b = np.r_[rotate_z(ab.base_goal[:3], theta), ab.base_goal[3] + theta]
        base_goal = (wa * aa.base_goal + wb * base_b) / (wa + wb)
        base_goal[3] = wrap(
            aa.base_goal[3] + wb / (wa + wb) * wrap(float(base_b[3] - aa.base_goal[3]))
        )
        action = replace(
            action,
            base_dmp=dmp_mod.merge([aa.base_dmp, ab.base_dmp], [wa, wb]),
            base_goal=base_goal,
        )
    perception = SalientPerceptions(
        cluster=cluster, weight=weight, room=room, scan=pa.scan, scan_pose=pa.scan_pose
    )
    return Smc(perception=perception, action=action)
