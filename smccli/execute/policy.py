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

Its parts: C_Now (:mod:`~smccli.execute.matching`), the decision's record
(:mod:`~smccli.execute.decision`), the readings (:mod:`~smccli.execute.observation`), the
rolled-out plan (:mod:`~smccli.execute.plan`) and looking again while an action runs
(:mod:`~smccli.execute.looking`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import mujoco
import numpy as np

from smccli.errors import SmcError, TreeError
from smccli.execute.decision import Candidate, Decision
from smccli.execute.grasp import (
    FingerColumns,
    clear_grasp,
    finger_columns,
    others,
    shifted,
    solid_neighbours,
)
from smccli.execute.looking import find_again
from smccli.execute.matching import EdgeStack, equivalent, match_arm, match_base, match_edges
from smccli.execute.observation import Observation
from smccli.execute.plan import STOPS, Plan, action_duration, rolled_out, switch_pose
from smccli.learn import frames
from smccli.learn.smc import Action
from smccli.learn.tree import ROOT, Edge, Tree
from smccli.perception import Cluster
from smccli.perception.cloud import object_points
from smccli.world.controller import CartesianController, reach_problem
from smccli.world.geometry import between
from smccli.world.robot import Robot
from smccli.world.sensors import CONTROL_PERIOD

__all__ = [
    "CONTROL_PERIOD",
    "STOPS",
    "Candidate",
    "Decision",
    "EdgeStack",
    "Observation",
    "Plan",
    "TreePolicy",
    "action_duration",
    "equivalent",
    "match_edges",
]


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
        self._fingers: FingerColumns | None = None
        self._held_shift = 0.0
        """How far from the demonstrated grasp the hand holds what it grasped, along its x
        [m]: every goal until it lets go moves with it (:mod:`~smccli.execute.grasp`)."""
        self._held_reach = 0.0
        """How far what the hand grasped reaches from the POI [m] (0: it grasped nothing):
        its last view's half diagonal, plus the grasp's shift."""

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
        self._held_shift = self._held_reach = 0.0

    @property
    def held_reach(self) -> float:
        """How far from the POI what the hand holds reaches [m]: 0 unless the last gripper
        event closed on an object (its view at the grasp decision, :attr:`Plan.cluster`).
        No look is taken where what it holds may stand between the camera and the goal
        (:func:`~smccli.execute.looking.held_in_the_way`)."""
        return self._held_reach

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
        if plan.event in ("close", "open"):
            held = plan.cluster if plan.event == "close" else None
            self._held_shift = plan.grasp_shift if held is not None else 0.0
            self._held_reach = (
                0.0
                if held is None
                else float(np.hypot(*held.extents[:2])) / 2 + abs(plan.grasp_shift)
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
        base_now = self._base_now(obs, edge)
        start = base_now if a.poi == "base" else obs.poi
        assert start is not None
        wrist = None if obs.joints is None or a.poi is not None else float(obs.joints[-1])
        goal = self.map_goal(
            a, cluster, start, edge.id, obs.lidar_pose, obs.base, edge.smc.perception.cluster, wrist
        )
        duration = action_duration(a, start, goal)
        dec = replace(dec, mapped_goal=goal, duration=duration)
        base_goal = None
        if a.base_dmp is not None and a.base_goal is not None and base_now is not None:
            base_goal = frames.map_base_goal(a, cluster, base_now, obs.poi)
        problem = self._reach_problem(a, goal, base_now, base_goal)
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
        base = None if base_goal is None or base_now is None else (base_now, base_goal)
        opening, shift = None, 0.0
        if self._grasps_on(a, cluster) and obs.camera is not None and cluster is not None:
            goal, opening, shift = self._room_for_fingers(
                obs, a, start, goal, cluster, control_period
            )
            dec = replace(dec, mapped_goal=goal)
        elif self._held_shift and a.poi is None and a.goal_frame in ("object", "world"):
            # What the hand holds sits that much off where the demonstration held it: the
            # hand goes that much further, so the object ends where it was taught to.
            shift = self._held_shift
            goal = shifted(goal, shift)
            dec = replace(dec, mapped_goal=goal)
        return rolled_out(
            dec,
            edge.id,
            a,
            start,
            goal,
            control_period,
            base=base,
            scan_alignment=self._scan_alignment.get(edge.id) if a.goal_frame == "scan" else None,
            cluster=cluster if a.goal_frame == "object" and a.poi is None else None,
            opening=opening,
            grasp_shift=shift,
        )

    def _grasps_on(self, action: Action, cluster: Cluster | None) -> bool:
        """Whether ``action`` closes an arm's gripper on ``cluster``, the fingers opened
        before: a grasp whose fingers need room (:mod:`~smccli.execute.grasp`). Where on the
        way it closes does not matter: a demonstration's fragment may end a little after the
        fingers closed (measured: at 94 % of it, development seed 2 of the look-alike
        family), and the fingers go down beside the object all the same."""
        return (
            cluster is not None
            and self.model is not None
            and self.robot.gripper is not None
            and action.poi is None
            and action.event == "close"
            and action.goal_frame == "object"
            and action.gripper_start >= 0.5
        )

    def _room_for_fingers(
        self,
        obs: Observation,
        action: Action,
        start: np.ndarray,
        goal: np.ndarray,
        cluster: Cluster,
        control_period: float,
    ) -> tuple[np.ndarray, float, float]:
        """The grasp ``goal`` moved, and the fingers' opening, where the decision's cloud
        leaves its fingers room where they close (:func:`~smccli.execute.plan.switch_pose`,
        :func:`~smccli.execute.grasp.clear_grasp`). The move is along the goal's x: where
        the fingers close, near the end of the approach, the hand has the goal's yaw."""
        assert self.model is not None and obs.camera is not None
        if self._fingers is None:
            self._fingers = finger_columns(self.model, self.robot)
        opening = float(action.gripper_start)
        if self._fingers is None:
            return goal, opening, 0.0
        points, _, _ = object_points(
            obs.camera, obs.robot_geometry, self.params.perception, obs.base
        )
        closing = switch_pose(action, start, goal, control_period)
        beside = solid_neighbours(others(points, cluster), self.params.perception)
        _, opening, shift = clear_grasp(closing, opening, cluster, beside, self._fingers)
        return (shifted(goal, shift) if shift else goal), opening, shift

    def _base_now(self, obs: Observation, edge: Edge) -> np.ndarray | None:
        """A mobile manipulator's base now ``[x, y, 0, yaw]`` (its SMCs drive the hand or the
        base); None for a robot with one POI."""
        if edge.smc.action.poi is None:
            return None
        if obs.base is None:
            raise SmcError(
                f"observation at t={obs.t:.3f} s has no base: SMC {edge.id} drives a mobile "
                "manipulator (Observation.base)"
            )
        return np.array([obs.base[0], obs.base[1], 0.0, obs.base[2]])

    def _reach_problem(
        self,
        action: Action,
        goal: np.ndarray,
        base_now: np.ndarray | None,
        base_goal: np.ndarray | None,
    ) -> str | None:
        """Why the arm cannot reach ``goal`` (None: it can, or no model to tell). A mobile
        manipulator's hand goal is reached from where its base will stand."""
        if self.model is None or action.poi == "base":
            return None
        hand_goal = goal
        if base_now is not None and action.poi == "hand":
            stand = base_now if base_goal is None else base_goal
            hand_goal = between(stand[[0, 1, 3]], goal)
        return reach_problem(self.model, self.robot, hand_goal)

    def match(
        self, obs: Observation, nodes: tuple[str, ...] | None = None
    ) -> tuple[Decision, Edge | None, Cluster | None]:
        """C_Now of ``obs`` against the children of ``nodes`` (default the frontier): the
        decision (no goal mapped yet), the chosen edge and the context cluster it matched
        (:func:`~smccli.execute.matching.match_arm`; a mobile base:
        :func:`~smccli.execute.matching.match_base`, keeping its scans' alignments for
        :meth:`map_goal`)."""
        nodes = self._nodes if nodes is None else nodes
        stack = self.stack(nodes)
        if self.has_lidar and (
            not self.mobile_manipulator
            or any(e.smc.perception.room is not None for e in stack.edges)
        ):
            dec, edge, self._scan_alignment = match_base(obs, nodes, stack.edges, self.params)
            return dec, edge, None
        return match_arm(obs, nodes, stack, self.params)

    def _kinematics(self) -> CartesianController:
        """The arm's kinematics, as its controller sees them (built once)."""
        if self._controller is None:
            assert self.model is not None
            self._controller = CartesianController(self.model, self.robot)
        return self._controller

    def look_again(
        self, plan: Plan, seen: Cluster, clusters: Sequence[Cluster]
    ) -> tuple[Cluster, np.ndarray] | None:
        """Look again (:mod:`smccli.execute.looking`): the object ``plan`` acts on, last
        ``seen`` there, among ``clusters`` of a frame taken while the action runs, with the
        goal mapped on it; None where the goal stays (:func:`~smccli.execute.looking.find_again`).
        """
        edge = self.edge(plan.edge) if plan.edge is not None else None
        if edge is None or edge.smc.perception.cluster is None or plan.goal is None:
            return None
        taught = edge.smc.perception.cluster
        c = find_again(taught, seen, clusters, self.params)
        if c is None:
            return None
        # The goal's yaw nearest the one decided (its choice among equivalent yaws, e.g.
        # the one the wrist reaches inside its limits), from where the action started.
        start = np.r_[plan.poses[0][:3], plan.goal[3]]
        goal = self.map_goal(edge.smc.action, c, start, edge.id, taught=taught)
        return c, shifted(goal, plan.grasp_shift)  # the grasp's shift, as decided

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
        alignment of ``edge``'s scan at the last decision (:meth:`match`). ``wrist``:
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
