"""The ROS 1 layer (rospy): it only moves messages between a ROS master and the plain
Python of :mod:`smccli.ros.node` (``smc run --ros1``) and :mod:`smccli.ros.sim_robot`
(``smc sim --ros1``).

The node subscribes with ``rospy.AnyMsg`` and decodes the raw ROS 1 bytes with ``rosbags``'
ROS 1 typestore, the library ``smc compile`` reads ROS 1 bags with, so a message reads the
same live and from a bag (:mod:`smccli.ros.inbox` then uses compile's image and TF code).
What it publishes are rospy's generated messages.

rospy comes from Debian's packages (``python3-rospy`` and the message packages): their
folder is appended at the end of ``sys.path`` only here, so it never shadows the
environment's own packages (numpy ...).
"""

from __future__ import annotations

import sys
import threading
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from smccli.errors import SmcError
from smccli.logs.ros2_images import COMPRESSED_DEPTH_HEADER
from smccli.logs.topic_map import TopicMap
from smccli.ros.inbox import Inbox
from smccli.ros.node import Command
from smccli.world.geometry import matrix_quat, yaw_quat
from smccli.world.robot import Robot

if TYPE_CHECKING:  # the node's process never loads the simulator
    from smccli.ros.sim_robot import Readings, SimRobot

DIST_PACKAGES = "/usr/lib/python3/dist-packages"
DEB_PACKAGES = (
    "ros-core python3-rospy python3-std-msgs python3-sensor-msgs python3-geometry-msgs "
    "python3-trajectory-msgs python3-tf2-msgs python3-rosgraph-msgs"
)
"""What ``apt-get install`` needs on Debian bookworm (the Makefile's DEB_PKGS has them)."""
IDLE_PERIOD_S = 0.1
"""While no command comes, the simulated camera publishes this often (wall clock) [s]."""
NS = 1_000_000_000


def import_rospy() -> Any:
    """rospy, from Debian's ``dist-packages`` appended at the end of ``sys.path``;
    SmcError (exit 2) naming the packages to install when it is missing."""
    if DIST_PACKAGES not in sys.path:
        sys.path.append(DIST_PACKAGES)
    try:
        import rospy  # type: ignore[import-not-found]
        from geometry_msgs.msg import PoseStamped  # type: ignore[import-not-found]  # noqa: F401
        from sensor_msgs.msg import Image  # type: ignore[import-not-found]  # noqa: F401
        from trajectory_msgs.msg import JointTrajectory  # type: ignore[import-not-found]  # noqa: F401
    except ImportError as exc:
        raise SmcError(
            f"--ros1 needs rospy and ROS 1's messages ({exc.name} is missing): "
            f"sudo apt-get install {DEB_PACKAGES}"
        ) from None
    return rospy


class Ros1Decoder:
    """Raw ROS 1 messages (``rospy.AnyMsg``) -> ``rosbags`` ROS 1 messages."""

    def __init__(self) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.store = get_typestore(Stores.ROS1_NOETIC)

    def __call__(self, msg: Any) -> Any:
        kind = str(msg._connection_header["type"])  # sensor_msgs/Image
        name = kind.replace("/", "/msg/", 1)
        if name not in self.store.types:
            # The definition the publisher sends, as a ROS 1 bag stores it (rosbags'
            # AnyReader registers a bag's types the same way).
            from rosbags.typesys import get_types_from_msg

            text = str(msg._connection_header.get("message_definition", ""))
            self.store.register(get_types_from_msg(text, name))
        return self.store.deserialize_ros1(bytes(msg._buff), name)


def _compressed(topic: str) -> bool:
    """A topic image_transport's plugins name (``.../compressed``, ``.../compressedDepth``):
    the simulated camera publishes a CompressedImage there (PNG: lossless colour)."""
    return topic.rstrip("/").rsplit("/", 1)[-1] in ("compressed", "compressedDepth")


def _image_type(topic: str, raw: Any, compressed: Any) -> Any:
    return compressed if _compressed(topic) else raw


def _png(image: np.ndarray) -> bytes:
    import cv2

    ok, data = cv2.imencode(".png", image)
    assert ok
    return bytes(data)


def _stamp(rospy: Any, t_ns: int) -> Any:
    return rospy.Time(int(t_ns // NS), int(t_ns % NS))


class Ros1Node:
    """The :class:`~smccli.ros.node.Bus` of ``smc run --ros1``."""

    def __init__(self, topic_map: TopicMap, robot: Robot, wait_s: float) -> None:
        rospy = self.rospy = import_rospy()
        from geometry_msgs.msg import PoseStamped
        from std_msgs.msg import String
        from trajectory_msgs.msg import JointTrajectory

        rospy.init_node("smc_run", anonymous=True, disable_signals=True)
        self.inbox = Inbox(topic_map, robot)
        self.interrupted = False
        self.wait_s = wait_s
        decode = Ros1Decoder()
        inputs = ("joint_states", "color", "depth", "camera_info", "poi", "lidar", "weight")
        topics = [t for r, t in topic_map.topics.items() if r in inputs]
        self._subs = []
        for topic in [*topics, "/tf", "/tf_static"]:

            def on_message(msg: Any, topic: str = topic) -> None:
                received = time.perf_counter()
                try:
                    decoded = decode(msg)
                except Exception as exc:
                    with self.inbox.cond:
                        self.inbox.errors.append(f"{topic}: {exc}")
                    return
                self.inbox.add(topic, decoded, received)

            self._subs.append(
                rospy.Subscriber(topic, rospy.AnyMsg, on_message, queue_size=100, tcp_nodelay=True)
            )
        run = topic_map.run
        assert run is not None
        self._pose: Any = None
        self._arm: Any = None
        if run.arm:  # a joint-space arm: its targets replace the POI's
            self._arm = rospy.Publisher(run.arm, JointTrajectory, queue_size=100)
        elif run.command:
            self._pose = rospy.Publisher(run.command, PoseStamped, queue_size=100)
        self._grip = (
            rospy.Publisher(run.gripper, JointTrajectory, queue_size=100) if run.gripper else None
        )
        self._decision = rospy.Publisher("/smc/decision", String, queue_size=100, latch=True)
        self._state = rospy.Publisher("/smc/state", String, queue_size=100, latch=True)
        self._connected = False
        self.PoseStamped, self.JointTrajectory, self.String = PoseStamped, JointTrajectory, String

    def _wait_connected(self) -> None:
        """Commands go out only once the robot listens (rospy drops what it publishes to
        a topic before its subscribers connect)."""
        pubs = [p for p in (self._pose, self._arm, self._grip) if p]
        deadline = time.monotonic() + self.wait_s
        while any(p.get_num_connections() == 0 for p in pubs):
            if time.monotonic() > deadline or self.interrupted:
                names = ", ".join(p.resolved_name for p in pubs if p.get_num_connections() == 0)
                from smccli.ros.node import RobotStop

                raise RobotStop("stale_sensors", f"nothing subscribes to {names}")
            time.sleep(0.01)
        self._connected = True

    def send(self, cmd: Command) -> None:
        if not self._connected:
            self._wait_connected()
        stamp = _stamp(self.rospy, cmd.stamp_ns)
        if self._grip and cmd.finger_joints:
            self._grip.publish(self._trajectory(stamp, cmd.finger_joints, cmd.finger_positions))
        if self._arm:
            self._arm.publish(self._trajectory(stamp, cmd.arm_joints, cmd.arm_positions))
            return
        msg = self.PoseStamped()
        msg.header.stamp, msg.header.frame_id = stamp, cmd.frame
        p, q = msg.pose.position, msg.pose.orientation
        p.x, p.y, p.z = (float(v) for v in cmd.position)
        q.w, q.x, q.y, q.z = (float(v) for v in cmd.quaternion)
        self._pose.publish(msg)

    def _trajectory(self, stamp: Any, joints: tuple[str, ...], positions: tuple[float, ...]) -> Any:
        """A JointTrajectory of one point: ``positions`` of ``joints`` now."""
        from trajectory_msgs.msg import JointTrajectoryPoint

        msg = self.JointTrajectory()
        msg.header.stamp = stamp
        msg.joint_names = list(joints)
        msg.points = [JointTrajectoryPoint(positions=[float(v) for v in positions])]
        return msg

    def decision(self, text: str) -> None:
        self._decision.publish(self.String(data=text))

    def state(self, text: str) -> None:
        self._state.publish(self.String(data=text))

    def close(self, linger_s: float = 0.3) -> None:
        """Let the last messages leave, then leave the graph."""
        time.sleep(linger_s)
        self.rospy.signal_shutdown("smc run ended")


class Ros1Sim:
    """The ROS 1 side of ``smc sim --ros1``: publishes a :class:`SimRobot`'s readings and
    hands it the commands it receives."""

    def __init__(self, robot: SimRobot) -> None:
        rospy = self.rospy = import_rospy()
        from geometry_msgs.msg import PoseStamped
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import CameraInfo, CompressedImage, Image, JointState, LaserScan
        from std_msgs.msg import Float64
        from tf2_msgs.msg import TFMessage
        from trajectory_msgs.msg import JointTrajectory

        rospy.init_node("smc_sim", disable_signals=True)
        self.robot, m = robot, robot.map
        self.stopped = threading.Event()
        t = m.topics
        pub = rospy.Publisher
        self.pubs: dict[str, Any] = {
            "clock": pub("/clock", Clock, queue_size=10),
            "joint_states": pub(t["joint_states"], JointState, queue_size=100),
            "tf": pub("/tf", TFMessage, queue_size=100),
            **{
                role: pub(t[role], _image_type(t[role], Image, CompressedImage), queue_size=10)
                for role in ("color", "depth")
            },
            "camera_info": pub(t["camera_info"], CameraInfo, queue_size=10),
        }
        if "lidar" in t:
            self.pubs["lidar"] = pub(t["lidar"], LaserScan, queue_size=10)
        if "weight" in t:
            self.pubs["weight"] = pub(t["weight"], Float64, queue_size=100)
        self.msgs = {
            "Clock": Clock,
            "JointState": JointState,
            "TFMessage": TFMessage,
            "Image": Image,
            "CompressedImage": CompressedImage,
            "CameraInfo": CameraInfo,
            "LaserScan": LaserScan,
            "Float64": Float64,
        }
        assert m.run is not None
        inputs = [
            (m.run.command, PoseStamped, self._on_target),
            (m.run.arm, JointTrajectory, self._on_arm),
            (m.run.gripper, JointTrajectory, self._on_gripper),
        ]
        self._subs = [
            rospy.Subscriber(topic, kind, call, queue_size=1000, tcp_nodelay=True)
            for topic, kind, call in inputs
            if topic
        ]

    def _on_target(self, msg: Any) -> None:
        p, q = msg.pose.position, msg.pose.orientation
        self.robot.on_target(msg.header.stamp.to_nsec(), [p.x, p.y, p.z], [q.w, q.x, q.y, q.z])

    def _on_arm(self, msg: Any) -> None:
        if msg.points:
            self.robot.on_arm(
                msg.header.stamp.to_nsec(), list(msg.joint_names), list(msg.points[0].positions)
            )

    def _on_gripper(self, msg: Any) -> None:
        if msg.points:
            self.robot.on_gripper(
                msg.header.stamp.to_nsec(), list(msg.joint_names), list(msg.points[0].positions)
            )

    def spin(self) -> None:
        """Step on each complete command; publish the readings after it, and the camera's
        while the robot holds still; until :attr:`stopped` is set."""
        robot = self.robot
        self.publish(robot.readings(sensing=True))
        while not self.stopped.is_set():
            idle_at = time.monotonic() + IDLE_PERIOD_S
            with robot.cond:
                cmd = robot.next_command()
                while cmd is None and not self.stopped.is_set():
                    left = idle_at - time.monotonic()
                    if left <= 0:
                        break
                    robot.cond.wait(left)
                    cmd = robot.next_command()
            self.publish(robot.step(*cmd) if cmd is not None else robot.readings(sensing=True))

    def publish(self, r: Readings) -> None:
        rospy, M, m = self.rospy, self.msgs, self.robot.map
        stamp = _stamp(rospy, round(r.t * NS))
        self.pubs["clock"].publish(M["Clock"](clock=stamp))
        js = M["JointState"]()
        js.header.stamp = stamp
        driver = {ours: theirs for theirs, ours in m.joints.items()}
        js.name = [driver.get(n, n) for n in r.joints.names]
        js.position = [float(v) for v in r.joints.position]
        js.velocity = [float(v) for v in r.joints.velocity]
        js.effort = [float(v) for v in r.joints.effort]
        transforms = [self._tf(stamp, m.poi_frame or "tool", r.poi[:3], yaw_quat(r.poi[3]))]
        if r.frame is not None:
            from smccli.ros.sim_robot import CAMERA_FRAME

            T = r.frame.T_world_camera
            transforms.append(self._tf(stamp, CAMERA_FRAME, T[:3, 3], matrix_quat(T[:3, :3])))
        if r.lidar_pose is not None:
            from smccli.ros.sim_robot import LIDAR_FRAME

            x, y, yaw = r.lidar_pose
            transforms.append(self._tf(stamp, LIDAR_FRAME, [x, y, 0.0], yaw_quat(yaw)))
        self.pubs["tf"].publish(M["TFMessage"](transforms=transforms))
        if r.frame is not None:
            self._camera(stamp, r.frame)
        if r.scan is not None and "lidar" in self.pubs:
            self._scan(stamp, r.scan)
        if r.weight is not None and "weight" in self.pubs:
            self.pubs["weight"].publish(M["Float64"](data=float(r.weight)))
        # Joint states last: they mark a period as done for the node (its clock).
        self.pubs["joint_states"].publish(js)

    def _tf(self, stamp: Any, child: str, position: Any, quaternion: Any) -> Any:
        from geometry_msgs.msg import TransformStamped

        tr = TransformStamped()
        tr.header.stamp = stamp
        tr.header.frame_id = self.robot.map.world_frame
        tr.child_frame_id = child
        v, q = tr.transform.translation, tr.transform.rotation
        v.x, v.y, v.z = (float(a) for a in position)
        q.w, q.x, q.y, q.z = (float(a) for a in quaternion)
        return tr

    def _camera(self, stamp: Any, frame: Any) -> None:
        from smccli.ros.sim_robot import CAMERA_FRAME

        M, topics = self.msgs, self.robot.map.topics
        h, w = frame.depth.shape
        if _compressed(topics["color"]):
            color = M["CompressedImage"](format="rgb8; png compressed bgr8")
            color.data = _png(np.ascontiguousarray(frame.rgb[..., ::-1]))
        else:
            color = M["Image"](height=h, width=w, encoding="rgb8", step=3 * w)
            color.data = np.ascontiguousarray(frame.rgb, dtype=np.uint8).tobytes()
        if _compressed(topics["depth"]):
            # image_transport's compressedDepth: a header, then a 16-bit PNG in the map's
            # units (millimetres by default).
            units = np.round(frame.depth / self.robot.map.depth_scale)
            mm = np.clip(np.nan_to_num(units, posinf=0.0), 0, 65535).astype(np.uint16)
            depth = M["CompressedImage"](format="16UC1; compressedDepth png")
            depth.data = COMPRESSED_DEPTH_HEADER.pack(0, 0.0, 0.0) + _png(mm)
        else:
            depth = M["Image"](height=h, width=w, encoding="32FC1", step=4 * w)
            depth.data = np.ascontiguousarray(frame.depth, dtype="<f4").tobytes()
        info = M["CameraInfo"](height=h, width=w, distortion_model="plumb_bob")
        info.K = [float(v) for v in np.asarray(frame.K).reshape(9)]
        info.P = [*info.K[:3], 0.0, *info.K[3:6], 0.0, *info.K[6:], 0.0]
        info.R = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        info.D = [0.0] * 5
        for msg in (color, depth, info):
            msg.header.stamp, msg.header.frame_id = stamp, CAMERA_FRAME
        self.pubs["camera_info"].publish(info)
        self.pubs["depth"].publish(depth)
        self.pubs["color"].publish(color)

    def _scan(self, stamp: Any, scan: Any) -> None:
        n = len(scan.ranges)
        msg = self.msgs["LaserScan"](
            angle_min=float(scan.angle_min),
            angle_max=float(scan.angle_min + scan.angle_increment * (n - 1)),
            angle_increment=float(scan.angle_increment),
            range_min=0.0,
            range_max=float(scan.range_max),
            ranges=[float(v) for v in scan.ranges],
        )
        from smccli.ros.sim_robot import LIDAR_FRAME

        msg.header.stamp, msg.header.frame_id = stamp, LIDAR_FRAME
        self.pubs["lidar"].publish(msg)

    def close(self) -> None:
        self.rospy.signal_shutdown("smc sim ended")
