"""Algorithm 2 as a library: one call per decision point, for any runtime (paper 3.6, 3.9).

:class:`TreePolicy` walks an SMC tree one decision at a time. The robot gives what it
perceives at a decision point (:class:`Observation`: the RGB-D frame, its own geometry for
the self-filter, the scale, a mobile base's scan); :meth:`TreePolicy.decide` matches C_Now
against the children of the current node and takes the least D_P below T_hP (eq. 36, 39,
45), maps the chosen action's goal to the context (eq. 38-39, 46) and rolls its DMP out at
the robot's control period (:class:`Plan`). The robot executes the plan with its own
controller and calls :meth:`TreePolicy.advance`; the policy then stands at the child node.

The policy reads no clock, steps nothing and holds no sensor: the simulator's loop
(:class:`~smccli.execute.executor.TreeExecutor`) and a robot's (docs/on_a_robot.md) are
thin wrappers around it, and decide alike on the same readings.

Branches that differ only by their demonstrated path shape (same salient perception, same
gripper event, same goal in the object's frame) lead to equivalent decision points; the
policy keeps them all as its frontier and chooses among the union of their children (see
docs/replay.md, "frontier").
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import mujoco
import numpy as np

from smccli.errors import SmcError, TreeError
from smccli.learn import frames
from smccli.learn.contingency import d_p as d_p_stored
from smccli.learn.contingency import goal_gap, ranked
from smccli.learn.dmp import rollout
from smccli.learn.params import SmcParams
from smccli.learn.smc import Action
from smccli.learn.tree import ROOT, Edge, Tree
from smccli.perception import Cluster, cluster_unions, clusters_from_frame, d_cluster
from smccli.perception.distance import MIN_EXTENT, d_extents
from smccli.perception.histogram import BC_MIN
from smccli.perception.room import d_room, room_histogram
from smccli.perception.scan import Scan2D, align_scans, chamfer
from smccli.world.controller import CartesianController, reach_problem
from smccli.world.geometry import between
from smccli.world.robot import Robot
from smccli.world.sensors import CameraFrame, RobotGeometry

CONTROL_PERIOD = 0.01
"""Default control period of a plan's trajectory [s] (the simulator's)."""
DURATION_CLIP = (0.5, 2.5)
"""Bounds of the duration scale (new start-goal distance over the demonstrated one)."""
MAX_YAW_RATE = 1.5
"""A rollout lasts at least |yaw change| / this [s] (the wrist's comfortable speed) [rad/s]."""
MIN_DURATION = 0.5
"""Shortest rollout [s]."""
MIDWAY_PHASE = 0.95
"""A gripper switch before this phase of a fragment happens midway through the rollout."""

LOOK_RADIUS = 0.08
"""Looking again, the object acted on is sought this far from where it was last seen [m]:
a push of a few centimetres, not another object across the table."""
LOOK_MOVED = 0.01
"""It has moved when its centre is this far from where it was last seen [m]; less is the
noise of one view against another (a box's centre wanders 2-5 mm from frame to frame,
measured under the realistic sensors)."""
LOOK_MOVED_HIDDEN = 0.03
"""A partly hidden view (:attr:`Cluster.hidden`) has moved only this far [m]: its centre
is off by what the arm hides of it, 1-2 cm on bench_pick's box."""
LOOK_SAME_SIZE = 0.1
"""A partly hidden view counts only with its extents within this log-ratio (10 %) of the
last view's: a Panda's arm over a third of the box once moved its centre 5 cm (bench)."""
LOOK_BETTER = 0.02
"""A view that has not moved replaces the last one when its D_P to the taught perception is
this much lower: seen whole where it was partly hidden, not the noise of two views of one
pose (D_P 0.002-0.01 apart, measured on bench_pick)."""

STOPS = ("no_contingent_smc", "target_unreachable")
"""Why a plan may stop the task (:attr:`Plan.stop`)."""


# --- matching (eq. 36, 39, 45), vectorised over the candidate edges ------------------------


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
    log_brightness: np.ndarray
    """(E,): log of the stored relative brightness (NaN without one)."""
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
        bright = np.full(len(edges), np.nan)
        for i, c in enumerate(clusters):
            if c is not None:
                bright[i] = np.log(c.brightness)
                h = np.asarray(c.histogram, dtype=np.float64)
                hist[i] = np.sqrt(h / max(float(h.sum()), 1e-300))
                ext[i] = np.log(np.maximum(np.asarray(c.extents, dtype=np.float64), MIN_EXTENT))
        weights = [e.smc.perception.weight for e in edges]
        return cls(
            edges=edges,
            has_cluster=np.array([c is not None for c in clusters], dtype=bool),
            sqrt_hist=hist,
            log_ext=ext,
            log_brightness=bright,
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
            d_h = np.where(bc > 1.0 - 1e-12, 0.0, -np.log(np.maximum(bc, BC_MIN)))
            ec = np.log(
                np.maximum(np.array([c.extents for c in clusters], dtype=np.float64), MIN_EXTENT)
            )
            d_e = np.abs(stack.log_ext[:, None, :] - ec[None, :, :]).max(axis=2)
            dc = d_h / pp.hist_scale + d_e / pp.extent_scale
            rank = dc
            if pp.brightness_scale > 0:
                lb = np.log(np.array([c.brightness for c in clusters], dtype=np.float64))
                d_b = np.abs(stack.log_brightness[:, None] - lb[None, :])
                unknown = np.isnan(d_b)  # no table, too little of the sides, an old tree
                dc = dc + np.where(unknown, 0.0, d_b) / pp.brightness_scale
                unmeasured = unknown & ~np.isnan(stack.log_brightness)[:, None]
                rank = ranked(dc, unmeasured, params.t_hp)
            best = np.argmin(rank, axis=1)
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


def equivalent(a: Edge, b: Edge, params: SmcParams) -> bool:
    """Two sibling SMCs that differ at most by their path: same salient perceptions
    (D_P < T_hP), gripper event and goal frame, goals within T_hA once the object's
    symmetry is taken out (:func:`smccli.learn.contingency.goal_gap`)."""
    if goal_gap(a.smc, b.smc, params) >= params.t_ha:
        return False
    return d_p_stored(a.smc.perception, b.smc.perception, params) < params.t_hp


# --- what a decision point decided ---------------------------------------------------------


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
    """Context cluster matched to the SMC's localized perception (eq. 39), if any; from
    :attr:`Decision.n_clusters` on, a union of two neighbouring clusters
    (:func:`~smccli.perception.cluster_unions`)."""
    terms: tuple[tuple[str, float], ...] = ()
    """A mobile base's D_P by sensor (``room``, ``scan``), and the ICP fitness of the scan's
    alignment (``icp_fitness``, not part of D_P)."""


@dataclass(frozen=True, slots=True)
class Decision:
    """One decision point of Algorithm 2."""

    t: float
    """Time of the decision [s] (:attr:`Observation.t`: simulation or robot clock)."""
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
    """Wall time to perceive: extract the clusters (or the room's colours); the simulator
    loop adds the time to render and read its sensors [s]."""
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


def _num(x: float) -> float | None:
    return None if not math.isfinite(x) else float(x)


# --- what the robot gives and gets --------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Observation:
    """What the robot perceives at a decision point, once its last action has settled.

    Every pose is in one fixed frame, the "world" the demonstrations were recorded in (for
    an arm: the frame of its POI commands; for a mobile base: odometry's frame). Only what
    the current node's SMCs were taught with is needed; :meth:`TreePolicy.decide` names
    what is missing (SmcError).
    """

    t: float
    """Time of the readings [s] (any clock; it only stamps the decision)."""
    poi: np.ndarray
    """The POI now ``[x, y, z, yaw]`` [m, m, m, rad]: an arm's end-effector site, gripper
    pointing down; a mobile base's odometry pose (z = 0). The plan starts here."""
    camera: CameraFrame | None = None
    """The RGB-D frame (:class:`~smccli.world.sensors.CameraFrame`: rgb (H, W, 3) uint8,
    depth (H, W) [m] along the optical axis (0 where unknown), K (3, 3) [px],
    T_world_camera (4, 4) in the optical convention x right, y down, z forward). Needed
    by an arm's SMCs with an object and a base's with the room's colours."""
    robot_geometry: RobotGeometry | None = None
    """The robot's own links as spheres in the world frame, to remove them from the cloud
    (self-filter), e.g. ``RobotModel.from_mjcf(scene.mjcf, robot.joint_names)
    .geometry_for(joint_positions)`` (:mod:`smccli.world.robot_model`; positions in the
    order of ``robot.joint_names``). None: nothing is filtered (only safe when the robot is
    out of the camera's view)."""
    weight: float | None = None
    """The scale's reading at the decision point [kg], tared: the median of the last
    ``tree.params.weight_window`` seconds of readings
    (:func:`smccli.perception.scale_reading`). Needed by SMCs taught with a scale."""
    scan: Scan2D | None = None
    """A mobile base's lidar scan in the lidar's own frame. Needed by SMCs with a scan."""
    lidar_pose: np.ndarray | None = None
    """The lidar's pose ``[x, y, yaw]`` in odometry's frame when the scan was taken
    [m, m, rad]. Needed with ``scan``: it maps a goal stored relative to the taught scan."""
    joints: np.ndarray | None = None
    """An arm's joint readings in ``robot.arm_joints`` order, shape (n,) [rad]: which way
    its wrist turns to a goal (:meth:`TreePolicy.map_goal`). None: as the POI's yaw says."""
    base: np.ndarray | None = None
    """A mobile manipulator's base pose ``[x, y, yaw]`` from odometry [m, m, rad]; its
    ``poi`` is then the hand in odometry's frame (this pose composed with the hand in the
    base's frame, :func:`smccli.world.geometry.compose`)."""

    def __post_init__(self) -> None:
        self._vector("poi", "[x, y, z, yaw]")
        if self.lidar_pose is not None:
            self._vector("lidar_pose", "[x, y, yaw]")
        if self.base is not None:
            self._vector("base", "[x, y, yaw]")

    def _vector(self, name: str, form: str) -> None:
        """Store field ``name`` as float64, or SmcError unless it holds ``form``'s finite
        numbers."""
        raw = getattr(self, name)
        v = np.asarray(raw, dtype=np.float64)
        n = form.count(",") + 1
        if v.shape != (n,) or not np.all(np.isfinite(v)):
            raise SmcError(
                f"observation at t={self.t:.3f} s: {name} must be {n} finite numbers "
                f"{form}, got {np.asarray(raw).tolist()}"
            )
        object.__setattr__(self, name, v)


@dataclass(frozen=True, eq=False)
class Plan:
    """What to do after a decision point: the chosen action, mapped and rolled out.

    Execute it so (as :class:`~smccli.execute.executor.TreeExecutor` does): stream
    ``poses[1:]``, one per control period, with the gripper commanded to
    ``gripper_start``; at ``switch_index`` (when the switch is midway, ``switch_index <
    len(poses) - 1``) hold that pose until the POI is there, command ``gripper_end``, wait
    for the fingers to stop, and stream the rest with ``gripper_end``; hold ``goal`` until
    the POI is there; a switch at the end (``switch_index == len(poses) - 1``) comes now.
    Then :meth:`TreePolicy.advance`.
    """

    decision: Decision | None
    """The decision point (candidates with D_P, chosen edge, mapped goal, timings); None
    only when ``done`` (a leaf has no decision to make)."""
    edge: str | None = None
    """Id of the chosen edge (None when done or no SMC was contingent)."""
    goal: np.ndarray | None = None
    """The action's goal mapped to the context, ``[x, y, z, yaw]`` in the observation's
    frame (eq. 38-39, 46), the yaw unwrapped next to the start's."""
    times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(n,) time of each pose from the start of the action [s]: 0, one control period,
    ..., ``duration``. Empty when there is nothing to execute."""
    poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    """(n, 4) the rolled-out DMP ``[x, y, z, yaw]``: POI targets, ``poses[0]`` the start
    (the observation's POI), ``poses[-1]`` the goal."""
    gripper_start: float | None = None
    """Gripper command (1 open, 0 closed) from the start, None when nothing to execute."""
    gripper_end: float | None = None
    """Gripper command after the switch (same as ``gripper_start`` without one)."""
    switch_index: int | None = None
    """Index into ``poses`` where the gripper switches to ``gripper_end``; None: no switch."""
    gripper_switch: float | None = None
    """When the gripper switches, ``times[switch_index]`` [s from the start]; None: no switch."""
    event: str = "none"
    """The gripper event: ``close``, ``open`` or ``none``."""
    duration: float = 0.0
    """Duration of the rollout [s] (the demonstrated one scaled by the distance)."""
    done: bool = False
    """A leaf is reached: the task is over, there is nothing to execute."""
    stopped: bool = False
    """No action can be taken here (``stop`` says why, ``reason`` in one line)."""
    stop: str | None = None
    """``no_contingent_smc`` (no child SMC's perceptions match the context) or
    ``target_unreachable`` (the mapped goal is out of the arm's reach; checked only with
    a model), None otherwise (:data:`STOPS`)."""
    reason: str = ""
    """Why done or stopped, one line (the distances of every candidate at a stop)."""
    scan_alignment: np.ndarray | None = None
    """A mobile base's scan-frame goal: the current lidar in the taught lidar's frame, the
    SE(2) transform (3, 3) that mapped the goal (for correcting the goal while driving)."""
    poi: str | None = None
    """A mobile manipulator's: what ``poses`` drive, ``"hand"`` (the hand in odometry's
    frame; send each in the frame of the base's target of the same tick) or ``"base"``
    (the base ``[x, y, 0, yaw]``; the hand rides along). None: the robot's one POI."""
    base_poses: np.ndarray | None = None
    """A mobile manipulator's hand plan that also drives the base: (n, 4) base targets
    ``[x, y, 0, yaw]`` on the same clock as ``poses`` (two DMPs, one duration)."""
    cluster: Cluster | None = None
    """The object an arm's goal was mapped on (a goal in its frame), where the decision saw
    it: the executor looks for it again while the action runs (:meth:`TreePolicy.look_again`)."""

    @property
    def midway(self) -> bool:
        """The gripper switches before the goal (hold ``poses[switch_index]`` there)."""
        return self.switch_index is not None and self.switch_index < len(self.poses) - 1


def action_duration(action: Action, start: np.ndarray, goal: np.ndarray) -> float:
    """The demonstrated duration scaled by the start-goal distance, so speeds stay human [s]."""
    dmp = action.dmp
    demo = float(np.linalg.norm(dmp.goal[:3] - dmp.start[:3]))
    new = float(np.linalg.norm(goal[:3] - start[:3]))
    scale = float(np.clip(new / max(demo, 1e-3), *DURATION_CLIP))
    return max(MIN_DURATION, dmp.duration * scale, abs(goal[3] - start[3]) / MAX_YAW_RATE)


# --- Algorithm 2, one decision at a time --------------------------------------------------


class TreePolicy:
    """Algorithm 2 one decision point at a time, for any runtime.

    ``tree``: the SMC tree; ``robot``: the robot it runs on (its file:
    :func:`smccli.world.robot.load_robot`, or ``scene.robot``); ``model``: a MuJoCo model
    holding the robot (``scene.model()``), to refuse goals out of the arm's reach
    (:func:`smccli.world.controller.reach_problem`); without one no reach check is made.

    The policy keeps the frontier (the current node and those equivalent to it):
    :meth:`decide` plans the next action from an :class:`Observation`, :meth:`advance`
    moves on once the robot has executed it, :attr:`done` at a leaf.
    """

    def __init__(self, tree: Tree, robot: Robot, model: mujoco.MjModel | None = None) -> None:
        taught = tree.robot.get("name") if tree.robot else None
        if taught is not None and taught != robot.name:
            raise TreeError(
                f"tree taught on robot {taught!r}, not {robot.name!r}; a tree runs only on "
                "the robot it was taught on"
            )
        self.tree = tree
        self.params = tree.params
        self.robot = robot
        self.model = model
        self.has_lidar = any(s.type == "lidar" for s in robot.sensors)
        """The robot has a 2-D lidar: it decides as a mobile base (room colours, scans)."""
        self.mobile_manipulator = robot.base is not None and bool(robot.arm_joints)
        """Base and arm: a node whose SMCs hold room colours decides as a base, the others
        as an arm (object clusters)."""
        self._edges = {e.id: e for e in tree.edges}
        self._stacks: dict[tuple[str, ...], EdgeStack] = {}
        self._scan_alignment: dict[str, np.ndarray] = {}
        """At a base's decision: each matched edge's scan alignment T (3, 3)."""
        self._nodes: tuple[str, ...] = (ROOT,)
        self._controller: CartesianController | None = None

    # --- the frontier ----------------------------------------------------------------------

    @property
    def nodes(self) -> tuple[str, ...]:
        """The frontier: the current node and the nodes equivalent to it."""
        return self._nodes

    @property
    def done(self) -> bool:
        """A leaf is reached: no node of the frontier has a child."""
        return not any(self.tree.children(n) for n in self._nodes)

    def reset(self, node: str = ROOT) -> None:
        """Back to the root (a new task), or to ``node`` (where a person just taught the
        robot to be)."""
        if node != ROOT and node not in self.tree.nodes:
            raise SmcError(f"the tree has no node {node!r}")
        self._nodes = (node,)
        self._scan_alignment = {}

    def edge(self, edge_id: str) -> Edge:
        """The tree's edge ``edge_id`` (its SMC: perception and action)."""
        try:
            return self._edges[edge_id]
        except KeyError:
            raise SmcError(f"the tree has no edge {edge_id!r}") from None

    def stack(self, nodes: tuple[str, ...]) -> EdgeStack:
        """The children of ``nodes``, stacked for matching (cached)."""
        if nodes not in self._stacks:
            edges = [e for n in nodes for e in self.tree.children(n)]
            self._stacks[nodes] = EdgeStack.build(edges)
        return self._stacks[nodes]

    def advance(self, plan: Plan) -> None:
        """The robot has executed ``plan``: stand at the chosen edge's child (and the children
        of the siblings equivalent to it)."""
        if plan.decision is None or plan.edge is None:
            what = "done" if plan.done else f"stopped ({plan.stop})"
            raise SmcError(f"advance: the plan is {what}; there is no action to advance past")
        if plan.decision.nodes != self._nodes:
            raise SmcError(
                f"advance: the plan was decided at node {plan.decision.nodes[0]}, the policy "
                f"stands at node {self._nodes[0]}"
            )
        siblings = self.stack(self._nodes).edges
        edge = next((e for e in siblings if e.id == plan.edge), None)
        if edge is None:
            raise SmcError(f"advance: edge {plan.edge} does not leave node {self._nodes[0]}")
        self._nodes = tuple(
            e.child for e in siblings if e is edge or equivalent(e, edge, self.params)
        )

    # --- a decision point -----------------------------------------------------------------

    def decide(self, obs: Observation, control_period: float = CONTROL_PERIOD) -> Plan:
        """Plan the next action from ``obs``: match, choose (eq. 36, 45), map the goal
        (eq. 38-39, 46) and roll the DMP out at ``control_period`` [s].

        Returns a done plan at a leaf and a stopped one when no child SMC is contingent or
        (with a model) the mapped goal is out of reach; the policy then stays where it is.
        SmcError (one line) when ``obs`` lacks a reading the current SMCs need.
        """
        if not control_period > 0:
            raise SmcError(f"decide: control_period must be > 0 s, got {control_period}")
        if self.done:
            return Plan(decision=None, done=True, reason=f"leaf reached (node {self._nodes[0]})")
        nodes = self._nodes
        dec, edge, cluster = self.match(obs)
        if edge is None:
            best = ", ".join(
                f"{c.edge} d_p={c.d_p:.3f}" for c in sorted(dec.candidates, key=lambda c: c.d_p)
            )
            return Plan(
                decision=dec,
                stopped=True,
                stop="no_contingent_smc",
                reason=f"no contingent SMC at node {nodes[0]} (T_hP={self.params.t_hp}): {best}",
            )
        a = edge.smc.action
        base_now = None
        if a.poi is not None:
            if obs.base is None:
                raise SmcError(
                    f"observation at t={obs.t:.3f} s has no base: SMC {edge.id} drives a mobile "
                    "manipulator (Observation.base)"
                )
            base_now = np.array([obs.base[0], obs.base[1], 0.0, obs.base[2]])
        start = base_now if a.poi == "base" else obs.poi
        assert start is not None
        goal = self.map_goal(
            a,
            cluster,
            start,
            edge.id,
            obs.lidar_pose,
            obs.base,
            edge.smc.perception.cluster,
            wrist=None if obs.joints is None or a.poi is not None else float(obs.joints[-1]),
        )
        duration = action_duration(a, start, goal)
        dec = replace(dec, mapped_goal=goal, duration=duration)
        base_goal = None
        if a.base_dmp is not None and a.base_goal is not None and base_now is not None:
            base_goal = frames.map_base_goal(a, cluster, base_now, obs.poi)
        # A mobile manipulator's hand goal is reached from where its base will stand.
        hand_goal = goal
        if base_now is not None and a.poi == "hand":
            stand = base_now if base_goal is None else base_goal
            hand_goal = between(stand[[0, 1, 3]], goal)
        problem = (
            None
            if self.model is None or a.poi == "base"
            else reach_problem(self.model, self.robot, hand_goal)
        )
        if problem is not None:
            return Plan(
                decision=dec,
                edge=edge.id,
                goal=goal,
                duration=duration,
                event=a.event,
                stopped=True,
                stop="target_unreachable",
                reason=f"edge {edge.id}: goal [{goal[0]:.3f}, {goal[1]:.3f}, {goal[2]:.3f}] m, "
                f"yaw {goal[3]:.2f} rad is out of reach: {problem}",
            )
        n_steps = max(2, round(duration / control_period)) + 1
        times, poses = rollout(a.dmp, start=start, goal=goal, duration=duration, n_steps=n_steps)
        base_poses = None
        if base_goal is not None and base_now is not None and a.base_dmp is not None:
            _, base_poses = rollout(
                a.base_dmp, start=base_now, goal=base_goal, duration=duration, n_steps=n_steps
            )
        n = len(poses)
        switch: int | None = None
        if a.event != "none":
            # A switch inside the fragment (e.g. grasp, then lift) comes at its phase (never
            # at the last pose, which means at the goal); else at the goal.
            midway = a.gripper_phase < MIDWAY_PHASE
            switch = min(int(round(a.gripper_phase * (n - 1))), n - 2) if midway else n - 1
        return Plan(
            decision=dec,
            edge=edge.id,
            goal=goal,
            times=times,
            poses=poses,
            # Closed means squeeze; open as demonstrated (fingers opened only part way past a
            # door's edge onto its handle).
            gripper_start=float(a.gripper_start) if a.gripper_start >= 0.5 else 0.0,
            gripper_end=float(a.gripper_end) if a.gripper_end >= 0.5 else 0.0,
            switch_index=switch,
            gripper_switch=None if switch is None else float(times[switch]),
            event=a.event,
            duration=duration,
            scan_alignment=self._scan_alignment.get(edge.id) if a.goal_frame == "scan" else None,
            poi=a.poi,
            base_poses=base_poses,
            cluster=cluster if a.goal_frame == "object" and a.poi is None else None,
        )

    def match(
        self, obs: Observation, nodes: tuple[str, ...] | None = None
    ) -> tuple[Decision, Edge | None, Cluster | None]:
        """C_Now of ``obs`` against the children of ``nodes`` (default the frontier): the
        decision (no goal mapped yet), the chosen edge and the context cluster it matched."""
        nodes = self._nodes if nodes is None else nodes
        if self.has_lidar and (
            not self.mobile_manipulator
            or any(e.smc.perception.room is not None for e in self.stack(nodes).edges)
        ):
            dec, edge = self._match_base(obs, nodes)
            return dec, edge, None
        stack = self.stack(nodes)
        self._require(obs, nodes, "camera", stack.has_cluster, "an object the camera sees")
        self._require(obs, nodes, "weight", stack.has_weight, "the scale's reading")
        t0 = time.perf_counter()
        clusters: tuple[Cluster, ...] = ()
        if obs.camera is not None:
            clusters = clusters_from_frame(
                obs.camera, obs.robot_geometry, self.params.perception, obs.base
            )
        perceive_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        d, idx = match_edges(stack, clusters, obs.weight, self.params)
        ok = d < self.params.t_hp
        n_seen, union_s = len(clusters), 0.0
        if not ok.any() and obs.camera is not None and n_seen >= 2 and stack.has_cluster.any():
            # Nothing contingent: the object may be in pieces (an open box's near wall and
            # its floor, apart across a band of depth holes). Its taught perception says
            # whether two neighbouring clusters together are it; only here, so a decision
            # a whole object makes is never changed.
            t1 = time.perf_counter()
            unions = cluster_unions(
                obs.camera, obs.robot_geometry, self.params.perception, obs.base
            )
            union_s = time.perf_counter() - t1
            if unions:
                d2, idx2 = match_edges(stack, unions, obs.weight, self.params)
                better = d2 < d
                d, idx = np.where(better, d2, d), np.where(better, idx2 + n_seen, idx)
                clusters = clusters + unions
                ok = d < self.params.t_hp
        chosen = int(np.argmin(np.where(ok, d, np.inf))) if ok.any() else None
        match_s = time.perf_counter() - t0 - union_s
        perceive_s += union_s
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
            perceive_s=perceive_s,
            match_s=match_s,
        )
        return dec, edge, cluster

    def _kinematics(self) -> CartesianController:
        """The arm's kinematics, as its controller sees them (built once)."""
        if self._controller is None:
            assert self.model is not None
            self._controller = CartesianController(self.model, self.robot)
        return self._controller

    def look_again(
        self, plan: Plan, seen: Cluster, clusters: Sequence[Cluster]
    ) -> tuple[Cluster, np.ndarray] | None:
        """Look again (issue 27): the object ``plan`` acts on, last ``seen`` there, among
        ``clusters`` of a frame taken while the action runs; with the goal mapped on it.

        A cluster is that object when it lies within :data:`LOOK_RADIUS` of where it was
        seen and its D_P to the SMC's taught perception is below T_hP; a whole view comes
        before one something hides part of (:attr:`Cluster.hidden`). The goal moves when
        the object has moved by more than :data:`LOOK_MOVED` (a partly hidden view:
        :data:`LOOK_MOVED_HIDDEN`, its size within :data:`LOOK_SAME_SIZE`), or when a
        whole view is clearer: the last one was partly hidden, or this one matches the
        taught one better by :data:`LOOK_BETTER`; else None. Which SMC runs is not
        reconsidered: decisions stay as the paper has them.
        """
        edge = self.edge(plan.edge) if plan.edge is not None else None
        if edge is None or edge.smc.perception.cluster is None or plan.goal is None:
            return None
        taught = edge.smc.perception.cluster
        pp = self.params.perception
        hid = pp.hidden_min_points
        found = [
            (c.hidden >= hid, d, c)
            for c in clusters
            if np.hypot(*(c.centroid[:2] - seen.centroid[:2])) <= LOOK_RADIUS
            and (d := d_cluster(c, taught, pp)) < self.params.t_hp
        ]
        if not found:
            return None
        hidden, d, c = min(found, key=lambda f: (f[0], f[1]))  # a whole view first
        moved = float(np.hypot(*(c.centroid[:2] - seen.centroid[:2])))
        if hidden:
            # Its centre is off by what is hidden: only a larger move counts, and only with
            # the whole object in view (the arm in front of its edge, not of a third of it).
            same_size = d_extents(c.extents, seen.extents) <= LOOK_SAME_SIZE
            if moved <= LOOK_MOVED_HIDDEN or not same_size:
                return None
        elif moved <= LOOK_MOVED:
            clearer = seen.hidden >= hid or d < d_cluster(seen, taught, pp) - LOOK_BETTER
            if not clearer:
                return None
        # The goal's yaw nearest the one decided (its choice among equivalent yaws, e.g.
        # the one the wrist reaches inside its limits), from where the action started.
        start = np.r_[plan.poses[0][:3], plan.goal[3]]
        goal = self.map_goal(edge.smc.action, c, start, edge.id, taught=taught)
        return c, goal

    def _match_base(self, obs: Observation, nodes: tuple[str, ...]) -> tuple[Decision, Edge | None]:
        """A mobile base's decision point (paper 4.2.4): the room's colours and the lidar
        scan against each child SMC's (eq. 36, 45); a scan is matched by aligning it to the
        stored one (ICP), whose transform then maps the goal (eq. 38-39, :meth:`map_goal`)."""
        edges = self.stack(nodes).edges
        has_room = np.array([e.smc.perception.room is not None for e in edges], dtype=bool)
        has_scan = np.array([e.smc.perception.scan is not None for e in edges], dtype=bool)
        self._require(obs, nodes, "camera", has_room, "the room's colours")
        self._require(obs, nodes, "scan", has_scan, "a lidar scan")
        self._require(obs, nodes, "lidar_pose", has_scan, "a lidar scan (and its pose)")
        t0 = time.perf_counter()
        room = None
        if obs.camera is not None:
            room = room_histogram(obs.camera.rgb, self.params.perception)
        perceive_s = time.perf_counter() - t0
        t1 = time.perf_counter()
        icp_s = 0.0
        self._scan_alignment = {}
        cands = []
        for e in edges:
            stored = e.smc.perception
            terms: list[tuple[str, float]] = []
            d = math.inf if stored.room is None else 0.0
            if stored.room is not None:
                assert room is not None
                terms.append(("room", d_room(room, stored.room, self.params.perception)))
            if stored.scan is not None:
                assert obs.scan is not None
                t2 = time.perf_counter()
                try:
                    al = align_scans(stored.scan, obs.scan, self.params.scan)
                except ValueError:  # too few returns (a blind lidar) to align
                    al = None
                icp_s += time.perf_counter() - t2
                if al is None:
                    d = math.inf
                else:
                    scale = self.params.scan.distance_scale
                    dist = chamfer(stored.scan, obs.scan, al.T_target_source, self.params.scan)
                    terms.append(("scan", dist / scale))
                    self._scan_alignment[e.id] = al.T_target_source
                    terms.append(("icp_fitness", al.fitness))
            if math.isfinite(d):
                d = sum(v for k, v in terms if k != "icp_fitness")
            cands.append(Candidate(e.id, e.parent, d, d < self.params.t_hp, None, tuple(terms)))
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
        return dec, edge

    def _require(
        self, obs: Observation, nodes: tuple[str, ...], name: str, needs: np.ndarray, what: str
    ) -> None:
        """SmcError when ``obs`` lacks ``name`` while the SMCs flagged in ``needs`` match on
        it."""
        if getattr(obs, name) is None and needs.any():
            edges = self.stack(nodes).edges
            ids = ", ".join(e.id for e, n in zip(edges, needs, strict=True) if n)
            raise SmcError(
                f"observation at t={obs.t:.3f} s has no {name}: SMC {ids} at node {nodes[0]} "
                f"match on {what} (Observation.{name})"
            )

    def map_goal(
        self,
        action: Action,
        cluster: Cluster | None,
        start: np.ndarray,
        edge: str | None = None,
        lidar_pose: np.ndarray | None = None,
        base: np.ndarray | None = None,
        taught: Cluster | None = None,
        wrist: float | None = None,
    ) -> np.ndarray:
        """:func:`smccli.learn.frames.map_goal` for this robot, a scan-frame goal with the
        alignment of ``edge``'s scan at the last decision (:meth:`_match_base`). ``wrist``:
        an arm's last joint now [rad]; with it, an object-frame goal's yaw is one the wrist
        reaches the short way, inside its limits, where the gripper's or the object's
        symmetry leaves a choice."""
        yaw_ok = None
        if wrist is not None and self.model is not None and not self.mobile_manipulator:
            controller = self._kinematics()
            yaw_ok = lambda g: controller.wrist_inside(controller.wrist_short_way(g, wrist))  # noqa: E731
        return frames.map_goal(
            action,
            cluster,
            start,
            gripper=self.robot.gripper is not None,
            alignment=self._scan_alignment.get(edge) if edge is not None else None,
            lidar_pose=lidar_pose,
            base=base,
            taught=taught,
            edge=edge,
            yaw_ok=yaw_ok,
        )
