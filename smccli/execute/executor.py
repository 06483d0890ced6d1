"""Algorithm 2 of the paper: executing an SMC tree through the robot's sensors (3.6, 3.9).

At each decision point the robot perceives through its sensors only (the rendered RGB-D
camera, the scale, its own joints for the self-filter), with the very code compile uses;
among the children of the current node it takes the SMC with the least D_P that satisfies
C_Now (eq. 36, 45); maps its action to the context (eq. 38-39, 46): start = the current POI,
goal = the matched cluster's location and yaw plus the stored offset (or the stored absolute
goal); rolls the DMP out, streams it through the same Cartesian controller as teleop, holds
the goal until the POI arrives, applies the gripper event and waits for the fingers to stop,
then moves to the child node, until a leaf.

Honesty (DESIGN.md section 2): :class:`TreeExecutor` only sees a
:class:`~smccli.execute.sensing.Sensors` facade (camera, scale, POI, joints, gripper, step)
and never imports :mod:`smccli.execute.evaluation`, which scores the episode afterwards from
the simulator's truth.

Branches that differ only by their demonstrated path shape (same salient perception, same
gripper event, same goal in the object's frame) lead to equivalent decision points; the
executor keeps them all as its frontier and chooses among the union of their children (see
docs/replay.md, "frontier").
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from smccli.execute.sensing import Sensors
from smccli.learn.contingency import d_p as d_p_stored
from smccli.learn.contingency import goal_gap
from smccli.learn.dmp import rollout
from smccli.learn.params import SmcParams
from smccli.learn.smc import TWO_PI, Action, goal_from_object
from smccli.learn.tree import ROOT, Edge, Tree
from smccli.perception import Cluster, clusters_from_frame, scale_reading
from smccli.perception.room import d_room, room_histogram
from smccli.perception.scan import align_scans, chamfer, map_goal, pose_to_se2, se2_to_pose
from smccli.world.controller import reachable, wrap
from smccli.world.sensors import CameraFrame, PoiCommand

CONTROL_OUTCOMES = ("success", "no_contingent_smc", "target_unreachable", "timeout")
"""How :meth:`TreeExecutor.run` ends: a leaf reached ("success", to be confirmed by the
evaluation), or one of the three control stops."""

ARRIVAL_TOLERANCE = 0.005
"""The hold after a rollout ends once the POI is this close to the goal [m] (as the
scripted operator's moves)."""
MAX_HOLD = 1.5
"""Longest hold of the goal after a rollout [s]."""
DURATION_CLIP = (0.5, 2.5)
"""Bounds of the duration scale (new start-goal distance over the demonstrated one)."""
MAX_YAW_RATE = 1.5
"""A rollout lasts at least |yaw change| / this [s] (the wrist's comfortable speed) [rad/s]."""
MIN_DURATION = 0.5
"""Shortest rollout [s]."""
RELOCALIZE_PERIOD = 0.5
"""While a base drives to a goal stored with a scan, it aligns its scan to that scan this
often and corrects its odometry-frame goal and path (closed loop: odometry drifts) [s]."""
RELOCALIZE_MIN_FITNESS = 0.3
"""An alignment corrects the goal only when this share of the current scan's returns lie
within ``inlier_distance`` of the stored scan (the robot still sees the stored place)."""
RELOCALIZE_MAX_STEP = (0.3, 0.2)
"""Largest correction one alignment may make [m, rad]; a larger one is a wrong match."""
MIDWAY_PHASE = 0.95
"""A gripper switch before this phase of a fragment happens midway through the rollout."""


# --- matching (eq. 36, 39, 45), vectorised over the candidate edges ------------------------


_BC_MIN = 1e-6
_MIN_EXTENT = 1e-3


@dataclass(frozen=True)
class EdgeStack:
    """The stored salient perceptions of a set of edges, stacked for fast matching."""

    edges: tuple[Edge, ...]
    has_cluster: np.ndarray
    """(E,) bool: the SMC has a localized (cluster) perception."""
    sqrt_hist: np.ndarray
    """(E, H): square root of each stored normalised histogram (zeros without a cluster)."""
    log_ext: np.ndarray
    """(E, 3): log of the stored extents, floored at 1 mm."""
    has_weight: np.ndarray
    """(E,) bool: the SMC has a scale reading."""
    weight: np.ndarray
    """(E,): stored weight [kg] (0 without)."""

    @classmethod
    def build(cls, edges: Sequence[Edge]) -> EdgeStack:
        edges = tuple(edges)
        clusters = [e.smc.perception.cluster for e in edges]
        size = next((len(c.histogram) for c in clusters if c is not None), 1)
        hist = np.zeros((len(edges), size))
        ext = np.zeros((len(edges), 3))
        for i, c in enumerate(clusters):
            if c is not None:
                h = np.asarray(c.histogram, dtype=np.float64)
                hist[i] = np.sqrt(h / max(float(h.sum()), 1e-300))
                ext[i] = np.log(np.maximum(np.asarray(c.extents, dtype=np.float64), _MIN_EXTENT))
        weights = [e.smc.perception.weight for e in edges]
        return cls(
            edges=edges,
            has_cluster=np.array([c is not None for c in clusters], dtype=bool),
            sqrt_hist=hist,
            log_ext=ext,
            has_weight=np.array([w is not None for w in weights], dtype=bool),
            weight=np.array([0.0 if w is None else float(w) for w in weights]),
        )


def match_edges(
    stack: EdgeStack, clusters: Sequence[Cluster], weight: float | None, params: SmcParams
) -> tuple[np.ndarray, np.ndarray]:
    """C_Now of the context against every stacked edge at once (eq. 36, 39).

    Returns (d_p (E,), cluster index (E,) int, -1 when the SMC has no cluster). Same values
    as :func:`smccli.learn.contingency.match_context` edge by edge (tested), in one matrix product.
    """
    n = len(stack.edges)
    d = np.zeros(n)
    idx = np.full(n, -1, dtype=np.int64)
    if stack.has_cluster.any():
        if clusters:
            pp = params.perception
            hc = np.array([c.histogram for c in clusters], dtype=np.float64)
            hc = np.sqrt(hc / np.maximum(hc.sum(axis=1, keepdims=True), 1e-300))
            bc = stack.sqrt_hist @ hc.T  # (E, C) Bhattacharyya coefficients
            d_h = np.where(bc > 1.0 - 1e-12, 0.0, -np.log(np.maximum(bc, _BC_MIN)))
            ec = np.log(
                np.maximum(np.array([c.extents for c in clusters], dtype=np.float64), _MIN_EXTENT)
            )
            d_e = np.abs(stack.log_ext[:, None, :] - ec[None, :, :]).max(axis=2)
            dc = d_h / pp.hist_scale + d_e / pp.extent_scale
            best = np.argmin(dc, axis=1)
            d = np.where(stack.has_cluster, dc[np.arange(n), best], 0.0)
            idx = np.where(stack.has_cluster, best, -1)
        else:
            d = np.where(stack.has_cluster, np.inf, 0.0)
    if stack.has_weight.any():
        if weight is None:
            d = np.where(stack.has_weight, np.inf, d)
        else:
            d = d + np.where(
                stack.has_weight, np.abs(weight - stack.weight) / params.weight_scale, 0.0
            )
    return d, idx


# --- what control decided and did --------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Candidate:
    """One child SMC considered at a decision point."""

    edge: str
    """Edge id."""
    node: str
    """Node it leaves."""
    d_p: float
    """D_P between the context and the SMC's salient perceptions (inf: not comparable)."""
    contingent: bool
    """C_Now: d_p < T_hP (eq. 36)."""
    cluster_index: int | None
    """Context cluster matched to the SMC's localized perception (eq. 39), if any."""
    terms: tuple[tuple[str, float], ...] = ()
    """A mobile base's D_P by sensor (``room``, ``scan``), and the ICP fitness of the scan's
    alignment (``icp_fitness``, not part of D_P)."""


@dataclass(frozen=True, slots=True)
class Decision:
    """One decision point of Algorithm 2."""

    t: float
    """Simulation time of the decision [s]."""
    nodes: tuple[str, ...]
    """The frontier: the current node and the nodes equivalent to it."""
    candidates: tuple[Candidate, ...]
    """Every child of the frontier with its distances."""
    chosen: str | None
    """Edge taken (least contingent D_P, eq. 45), None when none was contingent."""
    mapped_goal: np.ndarray | None
    """Goal of the chosen action in the world [x, y, z, yaw] (eq. 38-39, 46)."""
    n_clusters: int
    """Object clusters seen."""
    weight: float | None
    """Scale reading [kg], None without a scale."""
    perceive_s: float
    """Wall time to render and extract the clusters [s]."""
    match_s: float
    """Wall time to match the candidates [s]."""
    duration: float = 0.0
    """Rollout duration of the chosen action [s]."""
    icp_s: float = 0.0
    """Wall time of the scan alignments, part of ``match_s`` [s]."""
    lidar_pose: np.ndarray | None = None
    """A mobile base's lidar pose in odometry's frame at the decision ``[x, y, yaw]``."""

    @property
    def latency_s(self) -> float:
        """Decision latency: perceive + match [s]."""
        return self.perceive_s + self.match_s

    def to_json(self) -> dict[str, Any]:
        """The ``/smc/decision`` message (schemas/smc_decision.schema.json)."""
        return {
            "node": self.nodes[0],
            "nodes": list(self.nodes),
            "candidates": [
                {
                    "edge": c.edge,
                    "node": c.node,
                    "d_p": _num(c.d_p),
                    "contingent": c.contingent,
                    "cluster": c.cluster_index,
                    **({"terms": {k: _num(v) for k, v in c.terms}} if c.terms else {}),
                }
                for c in self.candidates
            ],
            "chosen": self.chosen,
            "mapped_goal": None
            if self.mapped_goal is None
            else [float(v) for v in self.mapped_goal],
            "n_clusters": self.n_clusters,
            "weight": self.weight,
            "duration": self.duration,
            "timings": {
                "perceive": self.perceive_s,
                "match": self.match_s,
                "icp": self.icp_s,
                "total": self.latency_s,
            },
            **(
                {"lidar_pose": [float(v) for v in self.lidar_pose]}
                if self.lidar_pose is not None
                else {}
            ),
        }


@dataclass(frozen=True, slots=True)
class ActionTrace:
    """What happened while one chosen action ran (sensor readings only)."""

    edge: str
    event: str
    """Gripper event: close, open or none."""
    t0: float
    """Start [s]."""
    t1: float
    """End, after the gripper settled [s]."""
    opening_before: float
    """Gripper opening when the action started [0-1]."""
    opening_after: float
    """Gripper opening after the event settled [0-1]."""
    arrived: bool
    """The POI reached the goal within the tolerance before the hold ran out."""


def _num(x: float) -> float | None:
    return None if not math.isfinite(x) else float(x)


def equivalent(a: Edge, b: Edge, params: SmcParams) -> bool:
    """Two sibling SMCs that differ at most by their path: same salient perceptions
    (D_P < T_hP), gripper event and goal frame, goals within T_hA once the object's
    symmetry is taken out (:func:`smccli.learn.contingency.goal_gap`)."""
    if goal_gap(a.smc, b.smc, params) >= params.t_ha:
        return False
    return d_p_stored(a.smc.perception, b.smc.perception, params) < params.t_hp


# --- Algorithm 2 ----------------------------------------------------------------------


class TreeExecutor:
    """Algorithm 2: SMC-aware control that walks ``tree`` from the root to a leaf through
    ``sensors`` only.

    At each decision point: perceive (:meth:`perceive`), match C_Now against the frontier's
    children and take the least D_P below T_hP (eq. 36, 39, 45; :meth:`decide`), map the
    action's goal to the context (eq. 38-39, 46; :meth:`map_goal`), roll out the DMP and
    stream it (:meth:`execute`). ``on_decision`` (the replay log) observes each decision;
    ``max_time`` bounds the sim time before a ``timeout`` stop [s].
    """

    def __init__(
        self,
        tree: Tree,
        sensors: Sensors,
        on_decision: Callable[[Decision, CameraFrame, np.ndarray], None] | None = None,
        max_time: float = 120.0,
    ) -> None:
        self.tree = tree
        self.params = tree.params
        self.sensors = sensors
        self.on_decision = on_decision
        self.max_time = max_time
        self._stacks: dict[tuple[str, ...], EdgeStack] = {}
        self._last_cmd = PoiCommand(sensors.t, sensors.poi(), 1.0)
        self._scan_alignment: dict[str, np.ndarray] = {}
        """At a base's decision: each matched edge's scan alignment T (3, 3)."""
        self._weights: deque[tuple[float, float]] = deque()
        """Recent scale readings (t [s], kg), the last ``weight_window`` of them."""

    # perception at a decision point: the same pipeline and instants as compile
    def perceive(self) -> tuple[CameraFrame, tuple[Cluster, ...], float | None, float]:
        t0 = time.perf_counter()
        frame = self.sensors.render_camera()
        clusters = clusters_from_frame(frame, self.sensors.robot_geometry(), self.params.perception)
        elapsed = time.perf_counter() - t0
        weight = None
        if self.sensors.has_scale:
            # The same instant as compile (scale_reading): the window that ends here, the
            # decision point, where the last action has settled. At the first decision
            # there is no history yet: hold still and read it.
            window = self.params.weight_window
            while not self._weights or self._weights[0][0] > self.sensors.t - window + 1e-9:
                self.hold()
            t_w = np.array([t for t, _ in self._weights])
            w_w = np.array([w for _, w in self._weights])
            weight = scale_reading(t_w, w_w, self.sensors.t, window)
        return frame, clusters, weight, elapsed

    def stack(self, nodes: tuple[str, ...]) -> EdgeStack:
        if nodes not in self._stacks:
            edges = [e for n in nodes for e in self.tree.children(n)]
            self._stacks[nodes] = EdgeStack.build(edges)
        return self._stacks[nodes]

    def decide(
        self, nodes: tuple[str, ...]
    ) -> tuple[Decision, Edge | None, Cluster | None, CameraFrame]:
        if self.sensors.has_lidar:
            return self.decide_base(nodes)
        t = self.sensors.t
        frame, clusters, weight, perceive_s = self.perceive()
        t0 = time.perf_counter()
        stack = self.stack(nodes)
        d, idx = match_edges(stack, clusters, weight, self.params)
        ok = d < self.params.t_hp
        chosen = int(np.argmin(np.where(ok, d, np.inf))) if ok.any() else None
        match_s = time.perf_counter() - t0
        cands = tuple(
            Candidate(e.id, e.parent, float(d[i]), bool(ok[i]), None if idx[i] < 0 else int(idx[i]))
            for i, e in enumerate(stack.edges)
        )
        edge = None if chosen is None else stack.edges[chosen]
        cluster = None if edge is None or idx[chosen] < 0 else clusters[int(idx[chosen])]
        dec = Decision(
            t=t,
            nodes=nodes,
            candidates=cands,
            chosen=None if edge is None else edge.id,
            mapped_goal=None,
            n_clusters=len(clusters),
            weight=weight,
            perceive_s=perceive_s,
            match_s=match_s,
        )
        return dec, edge, cluster, frame

    def decide_base(
        self, nodes: tuple[str, ...]
    ) -> tuple[Decision, Edge | None, None, CameraFrame]:
        """A mobile base's decision point (paper 4.2.4): the room's colours and the lidar
        scan against each child SMC's (eq. 36, 45); a scan is matched by aligning it to the
        stored one (ICP), whose transform then maps the goal (eq. 38-39, :meth:`map_goal`)."""
        t = self.sensors.t
        t0 = time.perf_counter()
        frame = self.sensors.render_camera()
        room = room_histogram(frame.rgb, self.params.perception)
        scan = self.sensors.lidar()
        lidar_pose = self.sensors.lidar_pose()
        perceive_s = time.perf_counter() - t0
        t1 = time.perf_counter()
        icp_s = 0.0
        self._scan_alignment = {}
        cands = []
        for e in self.stack(nodes).edges:
            stored = e.smc.perception
            terms: list[tuple[str, float]] = []
            d = math.inf if stored.room is None else 0.0
            if stored.room is not None:
                terms.append(("room", d_room(room, stored.room, self.params.perception)))
            if stored.scan is not None:
                t2 = time.perf_counter()
                try:
                    al = align_scans(stored.scan, scan, self.params.scan)
                except ValueError:  # too few returns (a blind lidar) to align
                    al = None
                icp_s += time.perf_counter() - t2
                if al is None:
                    d = math.inf
                else:
                    scale = self.params.scan.distance_scale
                    dist = chamfer(stored.scan, scan, al.T_target_source, self.params.scan)
                    terms.append(("scan", dist / scale))
                    self._scan_alignment[e.id] = al.T_target_source
                    terms.append(("icp_fitness", al.fitness))
            if math.isfinite(d):
                d = sum(v for k, v in terms if k != "icp_fitness")
            cands.append(Candidate(e.id, e.parent, d, d < self.params.t_hp, None, tuple(terms)))
        ok = [c for c in cands if c.contingent]
        chosen = min(ok, key=lambda c: c.d_p) if ok else None
        edge = (
            None
            if chosen is None
            else next(e for e in self.stack(nodes).edges if e.id == chosen.edge)
        )
        dec = Decision(
            t=t,
            nodes=nodes,
            candidates=tuple(cands),
            chosen=None if edge is None else edge.id,
            mapped_goal=None,
            n_clusters=0,
            weight=None,
            perceive_s=perceive_s,
            match_s=time.perf_counter() - t1,
            icp_s=icp_s,
            lidar_pose=lidar_pose,
        )
        return dec, edge, None, frame

    def map_goal(
        self, action: Action, cluster: Cluster | None, start: np.ndarray, edge: str | None = None
    ) -> np.ndarray:
        """Contingent action mapping of the goal (eq. 38-39, 46)."""
        if action.goal_frame == "scan":
            # G_now = L_now * T^-1 * G_rel, T = the current lidar in the demo lidar's frame,
            # from the alignment that matched the scan (decide_base).
            assert edge is not None, "a scan-frame goal is mapped for the edge that matched"
            T = self._scan_alignment[edge]
            lidar_now = self.sensors.lidar_pose()
            x, y, yaw = map_goal(action.goal[[0, 1, 3]], T, lidar_now)
            return np.array([x, y, 0.0, start[3] + wrap(float(yaw - start[3]))])
        if self.sensors.robot.gripper is None:  # a base's world goal: its heading as taught
            goal = np.array(action.goal, dtype=float)
            goal[3] = start[3] + wrap(float(goal[3] - start[3]))
            return goal
        # A parallel gripper is symmetric under a half turn, so the wrist may take the short
        # way round, unless the object grasped or held has no symmetry: then the half turn
        # would put its other side where the demonstration put this one.
        asymmetric = max(action.held_symmetry, action.symmetry if cluster else 0.0)
        flip = asymmetric < TWO_PI - 1e-6
        if action.goal_frame == "object" and cluster is not None:
            flip = flip and cluster.yaw_period < TWO_PI - 1e-6
            goal = goal_from_object(action.goal, cluster, near_yaw=float(start[3]), flip=flip)
        else:
            goal = np.array(action.goal, dtype=float)
            if flip:
                goal[3] = start[3] + math.remainder(float(goal[3] - start[3]), math.pi)
        goal[3] = start[3] + wrap(float(goal[3] - start[3]))
        return goal

    def duration(self, action: Action, start: np.ndarray, goal: np.ndarray) -> float:
        """The demonstrated duration scaled by the start-goal distance, so speeds stay human."""
        dmp = action.dmp
        demo = float(np.linalg.norm(dmp.goal[:3] - dmp.start[:3]))
        new = float(np.linalg.norm(goal[:3] - start[:3]))
        scale = float(np.clip(new / max(demo, 1e-3), *DURATION_CLIP))
        return max(MIN_DURATION, dmp.duration * scale, abs(goal[3] - start[3]) / MAX_YAW_RATE)

    def hold(self) -> None:
        """Repeat the last command for one control period."""
        c = self._last_cmd
        self._send(PoiCommand(self.sensors.t, c.target, c.gripper))

    def _send(self, cmd: PoiCommand) -> None:
        self._last_cmd = cmd
        s = self.sensors
        s.step(cmd)
        if s.has_scale:
            w = s.weight()
            if w is not None:
                self._weights.append((s.t, w))
            while self._weights and self._weights[0][0] < s.t - 2 * self.params.weight_window:
                self._weights.popleft()

    def execute(
        self, edge: Edge, start: np.ndarray, goal: np.ndarray, duration: float
    ) -> ActionTrace:
        """Stream the rollout, hold the goal until the POI arrives, then the gripper event."""
        a = edge.smc.action
        s = self.sensors
        t0 = s.t
        opening0 = s.gripper_opening()
        grip = 1.0 if a.gripper_start >= 0.5 else 0.0
        _, path = rollout(
            a.dmp,
            start=start,
            goal=goal,
            duration=duration,
            n_steps=max(2, round(duration / s.control_period)) + 1,
        )
        end = 1.0 if a.gripper_end >= 0.5 else 0.0
        # A gripper switch inside the fragment (e.g. grasp, then lift): stream the rollout to
        # that phase, hold there while the fingers move, then go on with the new opening.
        midway = a.event != "none" and a.gripper_phase < MIDWAY_PHASE
        k = int(round(a.gripper_phase * (len(path) - 1))) if midway else len(path) - 1
        if a.goal_frame == "scan" and edge.id in self._scan_alignment:
            goal = self._stream_relocalized(edge, path, goal)
        else:
            for y in path[1 : k + 1]:
                self._send(PoiCommand(s.t, y, grip))
        if midway:
            self._arrive(path[k], grip)
            self._gripper_event(path[k], end)
            for y in path[k + 1 :]:
                self._send(PoiCommand(s.t, y, end))
            grip = end
        arrived = self._arrive(goal, grip)
        if a.event != "none" and not midway:
            self._gripper_event(goal, end)
        return ActionTrace(
            edge=edge.id,
            event=a.event,
            t0=t0,
            t1=s.t,
            opening_before=opening0,
            opening_after=s.gripper_opening(),
            arrived=arrived,
        )

    def _stream_relocalized(self, edge: Edge, path: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Stream a base's rollout ``path`` (n, 4) while tracking the stored scan: every
        RELOCALIZE_PERIOD the current scan is aligned to it from odometry's prediction; the
        correction of where the demo's lidar frame sits in odometry's frame moves the rest of
        the path and the goal. Returns the corrected goal."""
        s = self.sensors
        stored = edge.smc.perception.scan
        assert stored is not None
        T0 = self._scan_alignment[edge.id]
        # D: the demo lidar's frame in today's odometry frame (D = L * T^-1).
        D = pose_to_se2(s.lidar_pose()) @ np.linalg.inv(T0)
        path = path.copy()
        next_fix = s.t + RELOCALIZE_PERIOD
        i = 1
        while i < len(path):
            self._send(PoiCommand(s.t, path[i], 1.0))
            i += 1
            if s.t < next_fix - 1e-9:
                continue
            next_fix = s.t + RELOCALIZE_PERIOD
            scan, L = s.lidar(), pose_to_se2(s.lidar_pose())
            try:
                al = align_scans(
                    stored, scan, self.params.scan, initial=np.linalg.inv(D) @ L, search=False
                )
            except ValueError:
                continue
            if al.fitness < RELOCALIZE_MIN_FITNESS:
                continue  # out of sight of the stored place: odometry alone from here
            D_new = L @ np.linalg.inv(al.T_target_source)
            cx, cy, cyaw = se2_to_pose(D_new @ np.linalg.inv(D))
            if math.hypot(cx, cy) > RELOCALIZE_MAX_STEP[0] or abs(cyaw) > RELOCALIZE_MAX_STEP[1]:
                continue
            C = D_new @ np.linalg.inv(D)
            path[i:] = _move_poses(path[i:], C)
            goal = _move_poses(goal[None, :], C)[0]
            D = D_new
        return goal

    def _arrive(self, target: np.ndarray, grip: float) -> bool:
        """Hold ``target`` until the POI is within the tolerance (at most MAX_HOLD)."""
        s = self.sensors
        for _ in range(round(MAX_HOLD / s.control_period)):
            if np.linalg.norm(s.poi()[:3] - target[:3]) < ARRIVAL_TOLERANCE:
                return True
            self._send(PoiCommand(s.t, target, grip))
        return bool(np.linalg.norm(s.poi()[:3] - target[:3]) < ARRIVAL_TOLERANCE)

    def _gripper_event(self, target: np.ndarray, opening: float) -> None:
        """Command ``opening`` and wait until the fingers stop, as the scripted operator."""
        s = self.sensors
        still, t_ev = 0, s.t
        while True:
            self._send(PoiCommand(s.t, target, opening))
            still = 0 if abs(s.gripper_speed()) > 0.02 else still + 1
            el = s.t - t_ev
            if (el > 0.15 and still >= 10) or el > 3.0:
                return

    def run(self) -> tuple[str, str, list[Decision], list[ActionTrace], list[Edge]]:
        """Algorithm 2 from the root to a leaf: (outcome, reason, decisions, actions, path);
        outcome is one of :data:`CONTROL_OUTCOMES`."""
        nodes: tuple[str, ...] = (ROOT,)
        decisions: list[Decision] = []
        actions: list[ActionTrace] = []
        path: list[Edge] = []
        t_start = self.sensors.t
        while True:
            if not any(self.tree.children(n) for n in nodes):
                return "success", "leaf reached", decisions, actions, path
            if self.sensors.t - t_start > self.max_time:
                return "timeout", f"no leaf after {self.max_time:.0f} s", decisions, actions, path
            dec, edge, cluster, frame = self.decide(nodes)
            if edge is None:
                decisions.append(dec)
                if self.on_decision:
                    self.on_decision(dec, frame, np.zeros((0, 3)))
                best = ", ".join(
                    f"{c.edge} d_p={c.d_p:.3f}" for c in sorted(dec.candidates, key=lambda c: c.d_p)
                )
                return (
                    "no_contingent_smc",
                    f"no contingent SMC at node {nodes[0]} (T_hP={self.params.t_hp}): {best}",
                    decisions,
                    actions,
                    path,
                )
            start = self.sensors.poi()
            goal = self.map_goal(edge.smc.action, cluster, start, edge.id)
            duration = self.duration(edge.smc.action, start, goal)
            dec = Decision(**{**_fields(dec), "mapped_goal": goal, "duration": duration})
            decisions.append(dec)
            if self.on_decision:
                self.on_decision(dec, frame, start)
            if not reachable(self.sensors.model, self.sensors.robot, goal):
                return (
                    "target_unreachable",
                    f"edge {edge.id}: goal [{goal[0]:.3f}, {goal[1]:.3f}, {goal[2]:.3f}] m, "
                    f"yaw {goal[3]:.2f} rad is out of reach",
                    decisions,
                    actions,
                    path,
                )
            actions.append(self.execute(edge, start, goal, duration))
            path.append(edge)
            siblings = self.stack(nodes).edges
            nodes = tuple(
                e.child for e in siblings if e is edge or equivalent(e, edge, self.params)
            )


def _move_poses(poses: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Base poses (n, 4) ``[x, y, z, yaw]`` moved by the SE(2) transform ``C`` (3, 3); yaws
    stay unwrapped."""
    out = poses.copy()
    out[:, :2] = poses[:, :2] @ C[:2, :2].T + C[:2, 2]
    out[:, 3] = poses[:, 3] + math.atan2(C[1, 0], C[0, 0])
    return out


def _fields(obj: Any) -> dict[str, Any]:
    return {f: getattr(obj, f) for f in obj.__slots__}
