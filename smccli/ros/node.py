"""``smc run TREE --ros1``: the tree drives a robot through its topics (docs/on_a_robot.md).

Plain Python, independent of the middleware: :class:`RobotSensors` is the same facade
replay's executor sees (:class:`smccli.execute.sensing.Sensors`), filled from the robot's
topics (:class:`~smccli.ros.inbox.Inbox`) instead of a simulator, so the very loop of
``smc replay`` (:class:`~smccli.execute.executor.TreeExecutor` around
:class:`~smccli.execute.policy.TreePolicy`) decides and streams. A command goes out through
a :class:`Bus` (:mod:`smccli.ros.ros1` moves the messages) and the robot's next joint state
says one control period has passed.

Time alignment: the robot's clock is its joint states' stamps. A decision reads the first
colour image stamped at or after the decision's time (the robot holds still meanwhile), the
depth image within 20 ms of it, the latest camera info and the camera's pose at the
image's stamp; a base's scan likewise.

Safety: every period the node checks that what it needs is fresh (camera, lidar, the POI's
and camera's transforms: newest stamp within ``stale_s`` of the robot's clock, or so within
``wait_s`` of wall time: it may be in flight) and that the robot answered within ``wait_s``
of wall time; otherwise, or on Ctrl-C, it stops
(:class:`RobotStop`): no further command, the robot holds its last target, the reason is
published and returned with an exit code (:data:`EXIT_CODES`).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from smccli.errors import SmcError
from smccli.execute.decision import Decision
from smccli.execute.executor import TreeExecutor
from smccli.learn.tree import Tree
from smccli.logs.ros2_bag import FRAME_MATCH_NS
from smccli.logs.topic_map import RunSpec, TopicMap
from smccli.perception.scan import Scan2D
from smccli.ros.inbox import Inbox
from smccli.world.controller import CartesianController, target_rotation
from smccli.world.geometry import matrix_quat, yaw_quat
from smccli.world.robot_model import RobotModel
from smccli.world.scene import Scene
from smccli.world.sensors import CameraFrame, JointState, PoiCommand, RobotGeometry

EXIT_CODES = {
    "success": 0,
    "no_contingent_smc": 1,
    "target_unreachable": 3,
    "stale_sensors": 4,
    "tf_lost": 5,
    "timeout": 6,
    "interrupted": 130,
}
"""How ``smc run`` ends -> its exit code (2 stays a bad input: tree, map, scene)."""
SLICE_S = 0.05
"""Waits look at the Ctrl-C flag this often [s]."""


class RobotStop(Exception):
    """The robot must stop now: ``stop`` (a key of :data:`EXIT_CODES`) and why."""

    def __init__(self, stop: str, reason: str) -> None:
        super().__init__(reason)
        self.stop, self.reason = stop, reason


@dataclass(frozen=True, slots=True)
class Command:
    """One control period's command: the POI target as a pose and the fingers' targets."""

    stamp_ns: int
    """The robot's time of the state it was computed from [ns]: the target and the gripper
    command of one period carry the same stamp."""
    frame: str
    """The world frame."""
    position: np.ndarray
    """POI target (3,) [m]."""
    quaternion: np.ndarray
    """Its orientation (4,) ``[w, x, y, z]``: an arm's tool down at the target's yaw, a
    base's heading."""
    finger_joints: tuple[str, ...] = ()
    """The gripper's joints (driver names), empty without a gripper command."""
    finger_positions: tuple[float, ...] = ()
    """Their targets [m or rad]."""
    arm_joints: tuple[str, ...] = ()
    """The arm's joints (driver names) for a robot commanded in joint space (``run.arm``)."""
    arm_positions: tuple[float, ...] = ()
    """Their targets [rad]: the POI target through the robot's Cartesian controller."""


class Bus(Protocol):
    """What the node needs of a middleware."""

    inbox: Inbox
    interrupted: bool
    """Set by the middleware on Ctrl-C (SIGINT)."""

    def send(self, cmd: Command) -> None: ...

    def decision(self, text: str) -> None: ...

    def state(self, text: str) -> None: ...


@dataclass
class NodeResult:
    """How a run ended and what it decided."""

    outcome: str
    """A key of :data:`EXIT_CODES`."""
    reason: str
    decisions: list[Decision] = field(default_factory=list)
    latency_s: list[float] = field(default_factory=list)
    """Wall time from the receipt of each decision's image to its first command [s]."""
    commands: int = 0

    @property
    def exit_code(self) -> int:
        return EXIT_CODES[self.outcome]

    def to_report(self) -> dict[str, object]:
        lat = [1e3 * v for v in self.latency_s]
        return {
            "outcome": self.outcome,
            "exit_code": self.exit_code,
            "reason": self.reason,
            "commands": self.commands,
            "decisions": [d.to_json() for d in self.decisions],
            "image_to_command_ms": lat,
        }


def command_for(
    cmd: PoiCommand,
    robot_scene: Scene,
    m: TopicMap,
    stamp_ns: int,
    ik: CartesianController | None = None,
) -> Command:
    """The :class:`Command` of a planned :class:`~smccli.world.sensors.PoiCommand`: an arm's
    target as its tool pointing down (:func:`~smccli.world.controller.target_rotation`), a
    base's as its heading; with ``ik`` (``run.arm``) the arm's joint targets it gives for
    it; the gripper's opening as finger joint targets."""
    robot = robot_scene.robot
    target = np.asarray(cmd.target, dtype=float)
    yaw = float(target[3])
    q = matrix_quat(target_rotation(yaw)) if robot.arm_joints else yaw_quat(yaw)
    driver = {ours: theirs for theirs, ours in m.joints.items()}
    joints: tuple[str, ...] = ()
    positions: tuple[float, ...] = ()
    g = robot.gripper
    if g is not None and m.run is not None and m.run.gripper is not None:
        joints = tuple(driver.get(j, j) for j in g.joints)
        q_f = g.closed + float(np.clip(cmd.gripper, 0.0, 1.0)) * (g.open - g.closed)
        positions = (q_f,) * len(joints)
    arm: tuple[str, ...] = ()
    arm_q: tuple[float, ...] = ()
    if ik is not None:
        arm = tuple(driver.get(j, j) for j in robot.arm_joints)
        arm_q = tuple(float(v) for v in ik.update(target))
    return Command(stamp_ns, m.world_frame, target[:3].copy(), q, joints, positions, arm, arm_q)


class RobotSensors:
    """The executor's :class:`~smccli.execute.sensing.Sensors` over a robot's topics.

    Reads nothing but the robot's messages; raises :class:`RobotStop` when they go stale,
    a transform is lost, the robot stops answering or Ctrl-C was pressed."""

    mobile_manipulator = False
    camera_windows = False
    """A camera gives whole frames (:attr:`smccli.execute.sensing.Sensors.camera_windows`)."""

    def __init__(self, bus: Bus, scene: Scene, topic_map: TopicMap, spec: RunSpec) -> None:
        self.bus, self.inbox, self.scene, self.map, self.spec = (
            bus,
            bus.inbox,
            scene,
            topic_map,
            spec,
        )
        self.model = scene.model()
        self.robot = scene.robot
        self.control_period = spec.period_s
        self.has_scale = scene.scale is not None and "weight" in topic_map.topics
        self.has_lidar = "lidar" in topic_map.topics
        self._body: RobotModel | None = None
        self._near = float(self.model.vis.map.znear * self.model.stat.extent)
        self._image_received: float | None = None
        """Receipt (wall clock) of the image of the decision just made, until its first
        command goes out."""
        self._frame_received: float | None = None
        """Receipt of the last image read."""
        self._decided_at: float | None = None
        self.latency_s: list[float] = []
        self.commands = 0
        self._ik: CartesianController | None = None
        """``run.arm``: the robot's Cartesian controller, turning POI targets into joint
        targets, started from the measured joints (:meth:`wait_ready`)."""
        if spec.arm is not None:
            if not self.robot.arm_joints:
                raise SmcError(f"robot {self.robot.name!r} has no arm: run.arm means nothing")
            self._ik = CartesianController(self.model, self.robot, control_period=spec.period_s)

    # --- clock and waiting ----------------------------------------------------------------

    @property
    def now_ns(self) -> int:
        return self.inbox.joint_stamp or 0

    @property
    def t(self) -> float:
        """The robot's clock: its newest joint state's stamp [s]."""
        return self.now_ns / 1e9

    def _wait(
        self,
        ready: Callable[[], bool],
        what: str,
        stop: str = "stale_sensors",
        timed_out: Callable[[], RobotStop] | None = None,
    ) -> None:
        """Wait (wall clock, at most ``wait_s``) until ``ready()`` holds, with the lock; on
        timeout raise ``timed_out()`` or a ``stop`` saying ``what``."""
        deadline = time.monotonic() + self.spec.wait_s
        with self.inbox.cond:
            while not ready():
                if self.bus.interrupted:
                    raise RobotStop("interrupted", "interrupted (Ctrl-C)")
                if self.inbox.errors:
                    raise RobotStop("stale_sensors", f"unreadable message: {self.inbox.errors[0]}")
                left = deadline - time.monotonic()
                if left <= 0:
                    if timed_out is not None:
                        raise timed_out()
                    raise RobotStop(stop, f"{what} (waited {self.spec.wait_s:g} s)")
                self.inbox.cond.wait(min(left, SLICE_S))

    def wait_ready(self) -> None:
        """Wait until every needed stream has spoken once (joints, the POI, the camera, a
        base's scan), then check they are fresh."""
        topics = self.map.topics
        self._wait(
            lambda: self.inbox.joint_stamp is not None,
            f"no joint states naming {', '.join(self.robot.joint_names)} on "
            f"{topics['joint_states']}",
        )
        self._wait(
            lambda: self.inbox.poi(self.now_ns) is not None,
            f"no POI in {self.map.world_frame!r} ({self._poi_source()})",
            stop="tf_lost",
        )
        self._wait(lambda: bool(self.inbox.color), f"no colour image on {topics['color']}")
        if "depth" in topics:
            self._wait(lambda: bool(self.inbox.depth), f"no depth image on {topics['depth']}")
        self._wait(lambda: self.inbox.K is not None, f"no camera info on {topics['camera_info']}")
        if self.has_lidar:
            self._wait(lambda: bool(self.inbox.scans), f"no scan on {topics['lidar']}")
        self._check()
        with self.inbox.cond:
            if self._ik is not None:
                position = self.inbox.joint_state().position
                names = self.robot.joint_names
                self._ik.reset(np.array([position[names.index(j)] for j in self.robot.arm_joints]))

    def _tf_at(self, frame: str, t_ns: int) -> bool:
        """Whether ``frame``'s chain to the world frame has its transforms up to ``t_ns``
        (lock held)."""
        reaches, newest = self.inbox.tf.freshness(frame)
        return reaches and (newest is None or newest >= t_ns)

    def _poi_at(self, t_ns: int) -> bool:
        if self.map.poi_frame is not None:
            return self._tf_at(self.map.poi_frame, t_ns)
        return bool(self.inbox.poses) and self.inbox.poses[-1][0] >= t_ns

    def _poi_source(self) -> str:
        if self.map.poi_frame is not None:
            return f"TF frame {self.map.poi_frame!r}"
        return f"topic {self.map.topics.get('poi')}"

    def _check(self) -> None:
        """RobotStop unless what the tree needs is fresh on the robot's clock.

        The clock is the joint states; an image or a transform travels on a connection of
        its own and may still be in flight when a later joint state is in (a simulator in
        lockstep runs many periods per second of wall time), so a stale stream gets
        ``wait_s`` of wall time to catch up before the robot is stopped."""
        stale: list[RobotStop] = []

        def fresh() -> bool:
            stale[:] = [s for s in [self._staleness()] if s is not None]
            return not stale

        self._wait(fresh, "", timed_out=lambda: stale[0])

    def _staleness(self) -> RobotStop | None:
        """Why the camera, lidar or a needed transform is stale now, or None (lock held)."""
        now, limit = self.now_ns, self.spec.stale_s
        topics = self.map.topics
        for role in ("color", "depth", "lidar") if self.has_lidar else ("color", "depth"):
            if role not in topics:
                continue
            newest = self.inbox.newest(role)
            age = math.inf if newest is None else (now - newest) / 1e9
            if age > limit:
                return RobotStop(
                    "stale_sensors",
                    f"{role} on {topics[role]}: newest message {age:.2f} s old at "
                    f"t={now / 1e9:.2f} s (limit {limit:g} s)",
                )
        frames = [self.inbox.color[-1][1]] if self.inbox.color else []
        if self.map.poi_frame is not None:
            frames.append(self.map.poi_frame)
        for frame in frames:
            reaches, newest = self.inbox.tf.freshness(frame)
            if not reaches:
                return RobotStop(
                    "tf_lost", f"no transform from {frame!r} to {self.map.world_frame!r}"
                )
            if newest is not None and (now - newest) / 1e9 > limit:
                return RobotStop(
                    "tf_lost",
                    f"transform {frame!r} -> {self.map.world_frame!r}: newest "
                    f"{(now - newest) / 1e9:.2f} s old at t={now / 1e9:.2f} s (limit {limit:g} s)",
                )
        return None

    # --- commands -------------------------------------------------------------------------

    def step(self, cmd: PoiCommand) -> None:
        """Send one period's command and wait for the robot's next joint state."""
        if self.bus.interrupted:
            raise RobotStop("interrupted", "interrupted (Ctrl-C)")
        sent = self.now_ns
        out = command_for(cmd, self.scene, self.map, sent, self._ik)
        self.bus.send(out)
        self._last = out
        self.commands += 1
        if self._image_received is not None:
            self.latency_s.append(time.perf_counter() - self._image_received)
            self._image_received = None
        period = round(self.control_period * 1e9)
        self._wait(
            lambda: self.now_ns >= sent + period - period // 10,
            f"no joint state on {self.map.topics['joint_states']} after the command at "
            f"t={sent / 1e9:.2f} s",
        )
        # Each topic has its own connection: the POI of this period may come after its
        # joint state.
        self._wait(
            lambda: self._poi_at(self.now_ns),
            f"no POI at t={self.now_ns / 1e9:.2f} s ({self._poi_source()})",
            stop="tf_lost",
        )
        self._check()

    def decided(self) -> None:
        """A decision was made from the last image read: its latency runs to the next
        command."""
        self._image_received = self._frame_received

    # --- readings -------------------------------------------------------------------------

    def poi(self) -> np.ndarray:
        with self.inbox.cond:
            p = self.inbox.poi(self.now_ns)
        if p is None:
            raise RobotStop("tf_lost", f"no POI in {self.map.world_frame!r} ({self._poi_source()})")
        return p

    def base(self) -> np.ndarray:
        raise SmcError("smc run: a mobile manipulator (base and arm) is not supported yet")

    def joint_state(self) -> JointState:
        with self.inbox.cond:
            return self.inbox.joint_state()

    def _fingers(self, column: int) -> np.ndarray:
        g = self.robot.gripper
        assert g is not None
        with self.inbox.cond:
            return np.array([self.inbox.joints[j][column] for j in g.joints])

    def gripper_opening(self) -> float:
        g = self.robot.gripper
        return 1.0 if g is None else g.opening(self._fingers(0))

    def gripper_speed(self) -> float:
        g = self.robot.gripper
        return 0.0 if g is None else g.opening_rate(self._fingers(1))

    def weight(self) -> float | None:
        with self.inbox.cond:
            return self.inbox.weight()

    def _fresh(self, series: Callable[[], object], what: str) -> None:
        """Wait for a reading stamped at or after now (the robot holds still meanwhile)."""
        now = self.now_ns

        def ready() -> bool:
            s = series()
            return bool(s) and s[-1][0] >= now  # type: ignore[index]

        self._wait(ready, f"no fresh {what} at t={now / 1e9:.2f} s")

    def lidar(self) -> Scan2D:
        return self._scan()[0]

    def lidar_pose(self) -> np.ndarray:
        return self._scan()[1]

    def _scan(self) -> tuple[Scan2D, np.ndarray]:
        self._fresh(lambda: self.inbox.scans, f"scan on {self.map.topics.get('lidar')}")
        stamp, frame_id = self.inbox.scans[-1][:2]
        self._wait(
            lambda: self._tf_at(frame_id, stamp),
            f"no transform from {frame_id!r} to {self.map.world_frame!r} at t={stamp / 1e9:.2f} s",
            stop="tf_lost",
        )
        with self.inbox.cond:
            got = self.inbox.scan(self.inbox.scans[-1][0])
        if isinstance(got, str):
            raise RobotStop("tf_lost" if "tf_lost" in got else "stale_sensors", got)
        return got

    def render_camera(
        self,
        region: tuple[int, int, int, int] | None = None,
        colour: bool = True,
        *,
        colour_later: bool = False,
    ) -> CameraFrame:
        """The first colour image stamped at or after now, with its depth (``region``,
        ``colour`` and ``colour_later`` are the simulator's rendering shortcuts: a camera
        gives whole frames, their colours received)."""
        self._fresh(lambda: self.inbox.color, f"colour image on {self.map.topics['color']}")
        stamp = self.inbox.color[-1][0]
        frame_id = self.inbox.color[-1][1]
        self._wait(
            lambda: any(abs(d[0] - stamp) <= FRAME_MATCH_NS for d in self.inbox.depth),
            f"no depth image within 20 ms of t={stamp / 1e9:.2f} s on "
            f"{self.map.topics.get('depth')}",
        )
        self._wait(
            lambda: self._tf_at(frame_id, stamp),
            f"no transform from {frame_id!r} to {self.map.world_frame!r} at t={stamp / 1e9:.2f} s",
            stop="tf_lost",
        )
        with self.inbox.cond:
            got = self.inbox.frame(stamp)
        if isinstance(got, str):
            raise RobotStop("tf_lost" if "tf_lost" in got else "stale_sensors", got)
        frame, self._frame_received = got
        return frame

    def camera_view(self) -> tuple[np.ndarray, np.ndarray, tuple[int, int], float]:
        """K, T_world_camera of the latest image, image shape (h, w), near distance [m]."""
        frame = self.render_camera()
        return frame.K, frame.T_world_camera, frame.depth.shape[:2], self._near  # type: ignore[return-value]

    def camera_near(self) -> float:
        """The near clipping distance of the scene's camera model [m]."""
        return self._near

    def robot_geometry(self) -> RobotGeometry:
        js = self.joint_state()
        if self._body is None:
            self._body = RobotModel.from_mjcf(self.scene.mjcf, js.names, dict(self.scene.assets))
        return self._body.geometry_for(js.position)


def run_node(
    tree: Tree,
    scene: Scene,
    topic_map: TopicMap,
    bus: Bus,
    *,
    max_time: float = 300.0,
    look_period: float | None = None,
) -> NodeResult:
    """Walk ``tree`` to a leaf on the robot behind ``bus`` (Algorithm 2, replay's loop);
    every decision is published (``/smc/decision``) and the state as it changes. Ends at a
    leaf, a policy stop or a :class:`RobotStop`; nothing is sent after it."""
    from smccli.execute.looking import LOOK_PERIOD

    assert topic_map.run is not None
    sensors = RobotSensors(bus, scene, topic_map, topic_map.run)
    decisions: list[Decision] = []

    def on_decision(dec: Decision, frame: CameraFrame, poi: np.ndarray) -> None:
        sensors.decided()
        decisions.append(dec)
        bus.decision(json.dumps(dec.to_json(), allow_nan=False))
        bus.state(f"deciding: {dec.nodes[0]} -> {dec.chosen or 'none'}")

    bus.state("waiting for the robot's topics")
    try:
        sensors.wait_ready()
        executor = TreeExecutor(
            tree,
            sensors,  # type: ignore[arg-type]
            on_decision=on_decision,
            max_time=max_time,
            look_period=LOOK_PERIOD if look_period is None else look_period,
        )
        bus.state("running")
        outcome, reason, *_ = executor.run()
    except RobotStop as stop:
        outcome, reason = stop.stop, stop.reason
    result = NodeResult(outcome, reason, decisions, sensors.latency_s, sensors.commands)
    bus.state(("done: " if outcome == "success" else f"stopped ({outcome}): ") + reason)
    return result
