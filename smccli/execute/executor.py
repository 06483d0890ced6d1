"""Algorithm 2 of the paper: executing an SMC tree through the robot's sensors (3.6, 3.9).

:class:`TreeExecutor` is the simulator's loop around :class:`~smccli.execute.policy.TreePolicy`,
which decides: at each decision point the robot perceives through its sensors only (the
rendered RGB-D camera, the scale, its own joints for the self-filter, a base's lidar), with
the very code compile uses; the policy takes among the children of the current node the SMC
with the least D_P that satisfies C_Now (eq. 36, 45), maps its action to the context (eq.
38-39, 46) and rolls the DMP out. The executor streams the rollout through the same
Cartesian controller as teleop, holds the goal until the POI arrives, applies the gripper
event and waits for the fingers to stop, then lets the policy move to the child node, until
a leaf.

Honesty (docs/design.md section 2): :class:`TreeExecutor` only sees a
:class:`~smccli.execute.sensing.Sensors` facade (camera, scale, POI, joints, gripper, step)
and never imports :mod:`smccli.execute.evaluation`, which scores the episode afterwards from
the simulator's truth.

The matching, the frontier and the goal mapping live in :mod:`smccli.execute.policy`, the
replay speed in :mod:`smccli.execute.speed`, looking again in :mod:`smccli.execute.looking`;
their names are re-exported here.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from smccli.execute.decision import Candidate, Decision
from smccli.execute.looking import (
    LOOK_NEAR,
    LOOK_PERIOD,
    check_look_period,
    held_in_the_way,
    look,
    look_crop,
    look_frame,
    steer,
)
from smccli.execute.matching import EdgeStack, equivalent, match_edges
from smccli.execute.observation import Observation
from smccli.execute.plan import DURATION_CLIP, MAX_YAW_RATE, MIDWAY_PHASE, MIN_DURATION, Plan
from smccli.execute.policy import TreePolicy
from smccli.execute.sensing import Sensors
from smccli.execute.speed import MAX_POI_SPEED, at_speed, check_speed, peak_speed, speed_limit
from smccli.execute.tracking import Track, still_there, track_of
from smccli.learn.dmp import rollout
from smccli.learn.tree import ROOT, Edge, Tree
from smccli.perception import Cluster, scale_reading
from smccli.perception.scan import align_scans
from smccli.world.controller import ARRIVAL_TOLERANCE, reachable
from smccli.world.geometry import between, compose, se2, se2_pose
from smccli.world.sensors import CameraFrame, PoiCommand

__all__ = [
    "ARRIVAL_TOLERANCE",
    "CONTROL_OUTCOMES",
    "DURATION_CLIP",
    "LOOK_PERIOD",
    "MAX_HOLD",
    "MAX_POI_SPEED",
    "MAX_YAW_RATE",
    "MIDWAY_PHASE",
    "MIN_DURATION",
    "RELOCALIZE_MAX_STEP",
    "RELOCALIZE_MIN_FITNESS",
    "RELOCALIZE_PERIOD",
    "ActionTrace",
    "Candidate",
    "Decision",
    "EdgeStack",
    "Observation",
    "Plan",
    "TreeExecutor",
    "TreePolicy",
    "at_speed",
    "check_look_period",
    "check_speed",
    "equivalent",
    "look_crop",
    "match_edges",
    "peak_speed",
    "speed_limit",
    "steer",
]

CONTROL_OUTCOMES = ("success", "no_contingent_smc", "target_unreachable", "timeout")
"""How :meth:`TreeExecutor.run` ends: a leaf reached ("success", to be confirmed by the
evaluation), or one of the three control stops."""

MAX_HOLD = 1.5
"""Longest hold of the goal after a rollout [s]."""
RETREAT = 0.08
"""After the tree's last action opened the gripper, an arm backs its hand out this far
along the approach axis (up) [m]: the demonstrations' own retreat comes after their last
mark, so no SMC holds it, and a one-jaw gripper's fixed jaw stayed on the object."""
RETREAT_SPEED = 0.15
"""Speed of that retreat [m/s] (the scripted operator's)."""
RELOCALIZE_PERIOD = 0.5
"""While a base drives to a goal stored with a scan, it aligns its scan to that scan this
often and corrects its odometry-frame goal and path (closed loop: odometry drifts) [s]."""
RELOCALIZE_MIN_FITNESS = 0.3
"""An alignment corrects the goal only when this share of the current scan's returns lie
within ``inlier_distance`` of the stored scan (the robot still sees the stored place)."""
RELOCALIZE_MAX_STEP = (0.3, 0.2)
"""Largest correction one alignment may make [m, rad]; a larger one is a wrong match."""


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


# --- Algorithm 2 ----------------------------------------------------------------------


class TreeExecutor:
    """Algorithm 2: SMC-aware control that walks ``tree`` from the root to a leaf through
    ``sensors`` only.

    At each decision point: observe (:meth:`observe`), let the policy match, choose and map
    the goal (:attr:`policy`, :meth:`TreePolicy.decide
    <smccli.execute.policy.TreePolicy.decide>`), stream the plan (:meth:`execute`) and
    advance the policy. ``on_decision`` (the replay log) observes each decision;
    ``max_time`` bounds the sim time before a ``timeout`` stop [s]; ``speed`` plays every
    DMP that many times faster (:func:`at_speed`; :func:`check_speed` bounds it);
    ``look_period``: how often an arm looks again at what it acts on (:meth:`execute`).
    """

    def __init__(
        self,
        tree: Tree,
        sensors: Sensors,
        on_decision: Callable[[Decision, CameraFrame, np.ndarray], None] | None = None,
        max_time: float = 120.0,
        speed: float = 1.0,
        look_period: float = LOOK_PERIOD,
    ) -> None:
        tree = at_speed(tree, speed)
        self.look_period = look_period
        """How often an arm looks again at the object it acts on [s]; 0 = never."""
        self.tree = tree
        self.params = tree.params
        self.sensors = sensors
        self.on_decision = on_decision
        self.max_time = max_time
        self.policy = TreePolicy(tree, sensors.robot, sensors.model)
        """Decides; the executor only reads the sensors and streams the plans."""
        self._last_cmd = PoiCommand(
            sensors.t,
            sensors.poi(),
            1.0,
            base=sensors.base() if sensors.mobile_manipulator else None,
        )
        self._plan_poi: str | None = None
        """The plan being streamed drives a mobile manipulator's ``hand`` or ``base``."""
        self._base_path: np.ndarray | None = None
        """Its base targets on the hand's clock (n, 4), when both move."""
        self._weights: deque[tuple[float, float]] = deque()
        """Recent scale readings (t [s], kg), the last ``weight_window`` of them."""
        self._frame: CameraFrame | None = None
        """The last decision point's camera frame."""

    # perception at a decision point: the same pipeline and instants as compile
    def observe(self) -> tuple[Observation, CameraFrame, float]:
        """The readings of a decision point: the observation, its camera frame, and the wall
        time spent rendering and reading the sensors [s] (not the scale's window)."""
        s = self.sensors
        t = s.t
        t0 = time.perf_counter()
        # The colours are drawn while perception works on the depth (DrawingFrame).
        frame = self._frame = s.render_camera(colour_later=True)
        if s.mobile_manipulator:  # every reading: a node decides as a base or as an arm
            scan, lidar_pose, geometry, base = (
                s.lidar(),
                s.lidar_pose(),
                s.robot_geometry(),
                s.base(),
            )
            acquire_s = time.perf_counter() - t0
            obs = Observation(
                t=t,
                poi=compose(base, s.poi()),
                camera=frame,
                robot_geometry=geometry,
                scan=scan,
                lidar_pose=lidar_pose,
                base=base,
            )
            return obs, frame, acquire_s
        if s.has_lidar:
            scan, lidar_pose = s.lidar(), s.lidar_pose()
            acquire_s = time.perf_counter() - t0
            obs = Observation(t=t, poi=s.poi(), camera=frame, scan=scan, lidar_pose=lidar_pose)
            return obs, frame, acquire_s
        geometry = s.robot_geometry()
        acquire_s = time.perf_counter() - t0
        weight = None
        if s.has_scale:
            # The same instant as compile (scale_reading): the window that ends here, the
            # decision point, where the last action has settled. At the first decision
            # there is no history yet: hold still and read it.
            window = self.params.weight_window
            while not self._weights or self._weights[0][0] > s.t - window + 1e-9:
                self.hold()
            t_w = np.array([t for t, _ in self._weights])
            w_w = np.array([w for _, w in self._weights])
            weight = scale_reading(t_w, w_w, s.t, window)
        obs = Observation(
            t=t,
            poi=s.poi(),
            camera=frame,
            robot_geometry=geometry,
            weight=weight,
            joints=self._arm_joints(),
        )
        return obs, frame, acquire_s

    def _arm_joints(self) -> np.ndarray | None:
        """The arm's joint readings in ``robot.arm_joints`` order [rad]; None without them."""
        names = self.sensors.robot.arm_joints
        js = self.sensors.joint_state()
        where = {n: i for i, n in enumerate(js.names)}
        if not names or any(n not in where for n in names):
            return None
        return np.array([js.position[where[n]] for n in names], dtype=float)

    def stack(self, nodes: tuple[str, ...]) -> EdgeStack:
        return self.policy.stack(nodes)

    def decide(
        self, nodes: tuple[str, ...]
    ) -> tuple[Decision, Edge | None, Cluster | None, CameraFrame]:
        """Observe and match at ``nodes`` (no goal mapped): the decision, the chosen edge,
        the cluster it matched and the camera frame."""
        obs, frame, acquire_s = self.observe()
        dec, edge, cluster = self.policy.match(obs, nodes)
        return replace(dec, perceive_s=acquire_s + dec.perceive_s), edge, cluster, frame

    def hold(self) -> None:
        """Repeat the last command for one control period."""
        c = self._last_cmd
        self._send(PoiCommand(self.sensors.t, c.target, c.gripper, base=c.base))

    def _cmd(self, pose: np.ndarray, grip: float, i: int | None = None) -> PoiCommand:
        """The command for a plan's pose ``pose`` (its ``i``-th; None: the goal). A mobile
        manipulator's hand pose goes out in the frame of the base's target of the same
        tick; a base pose moves the base, the hand's target riding along."""
        s, last = self.sensors, self._last_cmd
        if not s.mobile_manipulator:
            return PoiCommand(s.t, pose, grip)
        if self._plan_poi == "base":
            return PoiCommand(s.t, last.target, grip, base=np.asarray(pose)[[0, 1, 3]])
        base = last.base
        if self._base_path is not None:
            row = self._base_path[-1 if i is None else min(i, len(self._base_path) - 1)]
            base = row[[0, 1, 3]]
        assert base is not None
        return PoiCommand(s.t, between(base, pose), grip, base=base)

    def _poi_now(self) -> np.ndarray:
        """The POI the plan drives, now: a mobile manipulator's hand in odometry's frame, or
        its base ``[x, y, 0, yaw]``."""
        s = self.sensors
        if not s.mobile_manipulator:
            return s.poi()
        b = s.base()
        if self._plan_poi == "base":
            return np.array([b[0], b[1], 0.0, b[2]])
        return compose(b, s.poi())

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

    def execute(self, plan: Plan) -> ActionTrace:
        """Stream the plan's rollout, hold the goal until the POI arrives, then the gripper
        event (midway: at the switch's pose, before streaming the rest)."""
        assert plan.edge is not None and plan.goal is not None
        assert plan.gripper_start is not None and plan.gripper_end is not None
        edge = self.policy.edge(plan.edge)
        a = edge.smc.action
        s = self.sensors
        t0 = s.t
        opening0 = s.gripper_opening()
        grip, end, path, goal = plan.gripper_start, plan.gripper_end, plan.poses, plan.goal
        self._plan_poi, self._base_path = plan.poi, plan.base_poses
        # A gripper switch inside the fragment (e.g. grasp, then lift): stream the rollout to
        # that phase, hold there while the fingers move, then go on with the new opening.
        midway = plan.midway
        k = len(path) - 1 if plan.switch_index is None or not midway else plan.switch_index
        if plan.scan_alignment is not None:
            goal = self._stream_relocalized(edge, path, goal, plan.scan_alignment, grip)
        elif plan.cluster is not None and self.look_period > 0:
            path, goal = self._stream_looking(plan, path, goal, k, grip)
        else:
            for i in range(1, k + 1):
                self._send(self._cmd(path[i], grip, i))
        if midway:
            self._arrive(path[k], grip, k)
            self._gripper_event(path[k], end, k)
            for i in range(k + 1, len(path)):
                self._send(self._cmd(path[i], end, i))
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

    def _stream_relocalized(
        self, edge: Edge, path: np.ndarray, goal: np.ndarray, T0: np.ndarray, grip: float = 1.0
    ) -> np.ndarray:
        """Stream a base's rollout ``path`` (n, 4) while tracking the stored scan: every
        RELOCALIZE_PERIOD the current scan is aligned to it from odometry's prediction; the
        correction of where the demo's lidar frame sits in odometry's frame moves the rest of
        the path and the goal. ``T0``: the decision's alignment. Returns the corrected goal."""
        s = self.sensors
        stored = edge.smc.perception.scan
        assert stored is not None
        # D: the demo lidar's frame in today's odometry frame (D = L * T^-1).
        D = se2(s.lidar_pose()) @ np.linalg.inv(T0)
        path = path.copy()
        next_fix = s.t + RELOCALIZE_PERIOD
        i = 1
        while i < len(path):
            self._send(self._cmd(path[i], grip, i))
            i += 1
            if s.t < next_fix - 1e-9:
                continue
            next_fix = s.t + RELOCALIZE_PERIOD
            scan, L = s.lidar(), se2(s.lidar_pose())
            try:
                al = align_scans(
                    stored, scan, self.params.scan, initial=np.linalg.inv(D) @ L, search=False
                )
            except ValueError:
                continue
            if al.fitness < RELOCALIZE_MIN_FITNESS:
                continue  # out of sight of the stored place: odometry alone from here
            D_new = L @ np.linalg.inv(al.T_target_source)
            correction = se2_pose(D_new @ np.linalg.inv(D))
            cx, cy, cyaw = correction
            if math.hypot(cx, cy) > RELOCALIZE_MAX_STEP[0] or abs(cyaw) > RELOCALIZE_MAX_STEP[1]:
                continue
            # base poses [x, y, 0, yaw] move with the correction, yaws unwrapped
            path[i:] = compose(correction, path[i:])
            goal = compose(correction, goal)
            D = D_new
        return goal

    def _stream_looking(
        self, plan: Plan, path: np.ndarray, goal: np.ndarray, k: int, grip: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Stream ``path[1:k+1]`` (n, 4) of an arm's action on an object, looking at it
        again every ``look_period`` until the hand is within :data:`LOOK_NEAR` of where
        it acts (then the hand hides it), and not while what it holds is in the way: where
        it moved, or is seen better, the goal moves and the rest of the path with it
        (:func:`steer`). Returns (path, goal)."""
        s = self.sensors
        edge = self.policy.edge(plan.edge or "")
        seen = plan.cluster
        assert seen is not None
        act = path[k].copy()  # where the hand acts on it: the grasp, or the goal
        pp, near = self.params.perception, s.camera_near()
        # The decision's frame, where it saw the object: a look that finds it there to
        # the pixel is spared perceiving (smccli.execute.tracking).
        decided, track = self._frame, None
        if decided is not None and plan.decision is not None and decided.t == plan.decision.t:
            track = track_of(seen, decided, near, pp)
        next_look = s.t + self.look_period
        for i in range(1, k + 1):
            self._send(self._cmd(path[i], grip, i))
            if s.t < next_look - 1e-9 or i == k:
                continue
            next_look = s.t + self.look_period
            if np.linalg.norm(self._poi_now()[:3] - act[:3]) < LOOK_NEAR:
                continue
            if self._carried_in_the_way(seen):
                continue
            looked = self._look(seen, track)
            if looked is None:
                continue
            frame, clusters = looked
            found = self.policy.look_again(plan, seen, clusters)
            if found is None:
                continue
            seen, new_goal = found
            track = track_of(seen, frame, near, pp)
            new = rollout(
                edge.smc.action.dmp,
                start=path[0],
                goal=new_goal,
                duration=plan.duration,
                n_steps=len(path),
            )[1]
            path = steer(path, new, i)
            goal, act = new_goal, path[k].copy()
        return path, goal

    def _carried_in_the_way(self, seen: Cluster) -> bool:
        """What an arm's hand holds may hide ``seen`` from the camera
        (:func:`~smccli.execute.looking.held_in_the_way`): a look would not tell what it hides
        from a move."""
        reach = self.policy.held_reach
        if not reach or self.sensors.mobile_manipulator:
            return False  # (a mobile manipulator's POI is in its base's frame)
        return held_in_the_way(
            self.sensors, seen, self.params.perception, self._poi_now()[:3], reach
        )

    def _look(
        self, seen: Cluster, track: Track | None
    ) -> tuple[CameraFrame, tuple[Cluster, ...]] | None:
        """A look at ``seen``: None where its ``track`` finds it where it was (nothing
        perceived), else the look's frame and clusters."""
        s, pp = self.sensors, self.params.perception
        if track is not None and s.camera_windows:
            # The window around the object alone first, and its depth alone.
            if still_there(
                track, s.render_camera(track.region, colour=False), s.robot_geometry(), pp
            ):
                return None
            track = None
        frame = look_frame(s, seen, pp)
        if track is not None and still_there(track, frame, s.robot_geometry(), pp):
            return None
        return frame, look(s, seen, pp, frame)

    def _retreat(self) -> None:
        """Back the hand out of what it released: :data:`RETREAT` up along the approach
        axis at :data:`RETREAT_SPEED`, as far up as the arm reaches (an arm only: a mobile
        manipulator's hand rides its base's frame)."""
        s, last = self.sensors, self._last_cmd
        if s.mobile_manipulator:
            return
        start = np.asarray(last.target, dtype=float)
        goal = start.copy()
        for rise in (RETREAT, RETREAT / 2):
            goal[2] = start[2] + rise
            if reachable(s.model, s.robot, goal):
                break
        else:
            return
        n = max(2, round(float(goal[2] - start[2]) / RETREAT_SPEED / s.control_period))
        for k in range(1, n + 1):
            self._send(PoiCommand(s.t, start + (goal - start) * (k / n), last.gripper))
        self._arrive(goal, last.gripper)

    def _arrive(self, target: np.ndarray, grip: float, i: int | None = None) -> bool:
        """Hold ``target`` (the plan's ``i``-th pose) until the POI is within the tolerance
        (at most MAX_HOLD)."""
        s = self.sensors
        for _ in range(round(MAX_HOLD / s.control_period)):
            if np.linalg.norm(self._poi_now()[:3] - target[:3]) < ARRIVAL_TOLERANCE:
                return True
            self._send(self._cmd(target, grip, i))
        return bool(np.linalg.norm(self._poi_now()[:3] - target[:3]) < ARRIVAL_TOLERANCE)

    def _gripper_event(self, target: np.ndarray, opening: float, i: int | None = None) -> None:
        """Command ``opening`` and wait until the fingers stop, as the scripted operator."""
        s = self.sensors
        still, t_ev = 0, s.t
        while True:
            self._send(self._cmd(target, opening, i))
            still = 0 if abs(s.gripper_speed()) > 0.02 else still + 1
            el = s.t - t_ev
            if (el > 0.15 and still >= 10) or el > 3.0:
                return

    def run(
        self, start: str = ROOT
    ) -> tuple[str, str, list[Decision], list[ActionTrace], list[Edge]]:
        """Algorithm 2 from the root (or ``start``) to a leaf: (outcome, reason, decisions,
        actions, path); outcome is one of :data:`CONTROL_OUTCOMES`."""
        policy = self.policy
        policy.reset(start)
        decisions: list[Decision] = []
        actions: list[ActionTrace] = []
        path: list[Edge] = []
        t_start = self.sensors.t
        while True:
            if policy.done:
                if actions and actions[-1].event == "open":
                    self._retreat()
                return "success", "leaf reached", decisions, actions, path
            if self.sensors.t - t_start > self.max_time:
                return "timeout", f"no leaf after {self.max_time:.0f} s", decisions, actions, path
            obs, frame, acquire_s = self.observe()
            plan = policy.decide(obs, self.sensors.control_period)
            assert plan.decision is not None
            dec = replace(plan.decision, perceive_s=acquire_s + plan.decision.perceive_s)
            decisions.append(dec)
            if self.on_decision:
                self.on_decision(dec, frame, np.zeros((0, 3)) if plan.edge is None else obs.poi)
            if plan.stopped or plan.edge is None:
                assert plan.stop is not None
                return plan.stop, plan.reason, decisions, actions, path
            actions.append(self.execute(plan))
            path.append(policy.edge(plan.edge))
            policy.advance(plan)
