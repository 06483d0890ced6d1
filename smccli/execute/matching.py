"""C_Now at a decision point (eq. 36, 39, 45): the children of the frontier against what
the robot perceives now.

An arm's SMCs are matched on object clusters and the scale, every child at once
(:class:`EdgeStack`, :func:`match_edges`: :func:`smccli.learn.contingency.match_stack`);
a mobile base's on the room's colours and its lidar scan, aligned to the taught one by ICP
(:func:`match_base`). :func:`equivalent` says which siblings differ only by their path.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial

import numpy as np

from smccli.errors import SmcError
from smccli.execute.decision import Candidate, Decision
from smccli.execute.observation import Observation
from smccli.learn.contingency import StoredStack, goal_gap, match_stack
from smccli.learn.contingency import d_p as d_p_stored
from smccli.learn.params import SmcParams
from smccli.learn.tree import Edge
from smccli.perception import (
    Cluster,
    cluster_splits,
    cluster_unions,
    cluster_windows,
    clusters_from_frame,
)
from smccli.perception.room import d_room, room_histogram
from smccli.perception.scan import align_scans, chamfer


@dataclass(frozen=True)
class EdgeStack:
    """A set of edges with their stored salient perceptions stacked for fast matching."""

    edges: tuple[Edge, ...]
    stored: StoredStack
    """Their SMCs' salient perceptions, row by row."""

    @classmethod
    def build(cls, edges: Sequence[Edge]) -> EdgeStack:
        edges = tuple(edges)
        return cls(edges=edges, stored=StoredStack.build([e.smc.perception for e in edges]))

    @property
    def has_cluster(self) -> np.ndarray:
        """(E,) bool: the SMC has a localized (cluster) perception."""
        return self.stored.has_cluster

    @property
    def has_weight(self) -> np.ndarray:
        """(E,) bool: the SMC has a scale reading."""
        return self.stored.has_weight


def match_edges(
    stack: EdgeStack, clusters: Sequence[Cluster], weight: float | None, params: SmcParams
) -> tuple[np.ndarray, np.ndarray]:
    """C_Now of the context against every stacked edge at once (eq. 36, 39): D_P (E,) and
    the matched cluster's index (E,) int, -1 when the SMC has no cluster
    (:func:`~smccli.learn.contingency.match_stack`)."""
    return match_stack(stack.stored, clusters, weight, params)


def equivalent(a: Edge, b: Edge, params: SmcParams) -> bool:
    """Two sibling SMCs that differ at most by their path: same salient perceptions
    (D_P < T_hP), gripper event and goal frame, goals within T_hA once the object's
    symmetry is taken out (:func:`smccli.learn.contingency.goal_gap`)."""
    if goal_gap(a.smc, b.smc, params) >= params.t_ha:
        return False
    return d_p_stored(a.smc.perception, b.smc.perception, params) < params.t_hp


def require(
    obs: Observation,
    nodes: tuple[str, ...],
    edges: Sequence[Edge],
    name: str,
    needs: np.ndarray,
    what: str,
) -> None:
    """SmcError when ``obs`` lacks reading ``name`` while the ``edges`` flagged in ``needs``
    (E,) bool match on it (``what`` says what it is)."""
    if getattr(obs, name) is None and needs.any():
        ids = ", ".join(e.id for e, n in zip(edges, needs, strict=True) if n)
        raise SmcError(
            f"observation at t={obs.t:.3f} s has no {name}: SMC {ids} at node {nodes[0]} "
            f"match on {what} (Observation.{name})"
        )


def match_arm(
    obs: Observation, nodes: tuple[str, ...], stack: EdgeStack, params: SmcParams
) -> tuple[Decision, Edge | None, Cluster | None]:
    """An arm's decision point: the object clusters of ``obs``'s camera frame and its scale
    reading against the children ``stack`` of ``nodes`` (eq. 36, 39, 45). Returns the
    decision (no goal mapped yet), the chosen edge and the context cluster it matched."""
    require(obs, nodes, stack.edges, "camera", stack.has_cluster, "an object the camera sees")
    require(obs, nodes, stack.edges, "weight", stack.has_weight, "the scale's reading")
    t0 = time.perf_counter()
    clusters: tuple[Cluster, ...] = ()
    if obs.camera is not None:
        clusters = clusters_from_frame(obs.camera, obs.robot_geometry, params.perception, obs.base)
    perceive_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    d, idx = match_edges(stack, clusters, obs.weight, params)
    ok = d < params.t_hp
    n_seen, union_s = len(clusters), 0.0
    if obs.camera is not None and stack.has_cluster.any():
        # Nothing contingent: the object may be in pieces (an open box's near wall and
        # its floor, apart across a band of depth holes), or two objects touching may be
        # one cluster (a white box with a grey box against it). Its taught perception says
        # whether two neighbouring clusters together, or a piece of one divided by brightness
        # or height, are it, or else the end of a piece longer than the taught object
        # (one end to end with it), or else a part of the taught size of a piece too wide
        # or too short (one along its side, or across its end); each only where the
        # previous found nothing, so a decision the previous made is never changed. Pieces
        # and windows count only where they make an SMC contingent.
        taught = [e.smc.perception.cluster for e in stack.edges if e.smc.perception.cluster]
        sizes = tuple((float(c.extents[0]), float(c.extents[1])) for c in taught)
        ends = partial(cluster_windows, sizes=sizes)
        unknown = any(np.isnan(c.brightness) for c in taught)
        windows = partial(cluster_windows, sizes=sizes, ends_only=False, unknown_brightness=unknown)
        stages = (
            (cluster_unions, 2, False),
            (cluster_splits, 1, True),
            (ends, 1, True),
            (windows, 1, True),
        )
        for more, least, contingent_only in stages:
            if ok.any() or n_seen < least:
                continue
            t1 = time.perf_counter()
            extra = more(obs.camera, obs.robot_geometry, params.perception, obs.base)
            union_s += time.perf_counter() - t1
            if extra:
                d2, idx2 = match_edges(stack, extra, obs.weight, params)
                better = (d2 < d) & ((d2 < params.t_hp) | (not contingent_only))
                d, idx = np.where(better, d2, d), np.where(better, idx2 + len(clusters), idx)
                clusters = clusters + extra
                ok = d < params.t_hp
    chosen = int(np.argmin(np.where(ok, d, np.inf))) if ok.any() else None
    match_s = time.perf_counter() - t0 - union_s
    cands = tuple(
        Candidate(e.id, e.parent, float(d[i]), bool(ok[i]), None if idx[i] < 0 else int(idx[i]))
        for i, e in enumerate(stack.edges)
    )
    edge = None if chosen is None else stack.edges[chosen]
    cluster = None if edge is None or idx[chosen] < 0 else clusters[int(idx[chosen])]
    dec = Decision(
        t=obs.t,
        nodes=nodes,
        candidates=cands,
        chosen=None if edge is None else edge.id,
        mapped_goal=None,
        n_clusters=n_seen,
        weight=obs.weight,
        perceive_s=perceive_s + union_s,
        match_s=match_s,
    )
    return dec, edge, cluster


def match_base(
    obs: Observation, nodes: tuple[str, ...], edges: Sequence[Edge], params: SmcParams
) -> tuple[Decision, Edge | None, dict[str, np.ndarray]]:
    """A mobile base's decision point (paper 4.2.4): the room's colours and the lidar scan
    against each child SMC's ``edges`` of ``nodes`` (eq. 36, 45); a scan is matched by
    aligning it to the stored one (ICP). Returns the decision (no goal mapped yet), the
    chosen edge and each matched edge's scan alignment T (3, 3), which maps its goal
    (eq. 38-39)."""
    has_room = np.array([e.smc.perception.room is not None for e in edges], dtype=bool)
    has_scan = np.array([e.smc.perception.scan is not None for e in edges], dtype=bool)
    require(obs, nodes, edges, "camera", has_room, "the room's colours")
    require(obs, nodes, edges, "scan", has_scan, "a lidar scan")
    require(obs, nodes, edges, "lidar_pose", has_scan, "a lidar scan (and its pose)")
    t0 = time.perf_counter()
    room = None
    if obs.camera is not None:
        room = room_histogram(obs.camera.rgb, params.perception)
    perceive_s = time.perf_counter() - t0
    t1 = time.perf_counter()
    icp_s = 0.0
    alignments: dict[str, np.ndarray] = {}
    cands = []
    for e in edges:
        stored = e.smc.perception
        terms: list[tuple[str, float]] = []
        d = math.inf if stored.room is None else 0.0
        if stored.room is not None:
            assert room is not None
            terms.append(("room", d_room(room, stored.room, params.perception)))
        if stored.scan is not None:
            assert obs.scan is not None
            t2 = time.perf_counter()
            try:
                al = align_scans(stored.scan, obs.scan, params.scan)
            except ValueError:  # too few returns (a blind lidar) to align
                al = None
            icp_s += time.perf_counter() - t2
            if al is None:
                d = math.inf
            else:
                dist = chamfer(stored.scan, obs.scan, al.T_target_source, params.scan)
                terms.append(("scan", dist / params.scan.distance_scale))
                alignments[e.id] = al.T_target_source
                terms.append(("icp_fitness", al.fitness))
        if math.isfinite(d):
            d = sum(v for k, v in terms if k != "icp_fitness")
        cands.append(Candidate(e.id, e.parent, d, d < params.t_hp, None, tuple(terms)))
    ok = [c for c in cands if c.contingent]
    chosen = min(ok, key=lambda c: c.d_p) if ok else None
    edge = None if chosen is None else next(e for e in edges if e.id == chosen.edge)
    dec = Decision(
        t=obs.t,
        nodes=nodes,
        candidates=tuple(cands),
        chosen=None if edge is None else edge.id,
        mapped_goal=None,
        n_clusters=0,
        weight=None,
        perceive_s=perceive_s,
        match_s=time.perf_counter() - t1,
        icp_s=icp_s,
        lidar_pose=obs.lidar_pose,
    )
    return dec, edge, alignments
