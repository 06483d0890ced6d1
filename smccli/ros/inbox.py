"""What a running robot's topics said last, kept by the topic map's roles, and the readings
a decision takes from them: time alignment (the latest message at or before a time, a depth
image within 20 ms of its colour image, a pose at its own stamp through TF) and staleness.

Plain Python: the middleware (:mod:`smccli.ros.ros1`) hands each message here decoded as
``smc compile`` decodes a bag's (``rosbags``' ROS 1 types), from its own threads.
"""

from __future__ import annotations

import bisect
import threading
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from smccli.logs.decode import latest
from smccli.logs.ros2_bag import FRAME_MATCH_NS
from smccli.logs.ros2_images import ros_depth, ros_rgb
from smccli.logs.tf_buffer import TF_TOPICS, TfBuffer, stamp_ns
from smccli.logs.topic_map import TopicMap
from smccli.perception.scan import Scan2D
from smccli.world.geometry import quat_matrix, yaw_of
from smccli.world.robot import Robot
from smccli.world.sensors import CameraFrame, JointState

KEEP = 16
"""Messages kept per stream (and transforms per moving TF link)."""


class Inbox:
    """The latest messages of each mapped role, decoded; every method takes the lock.

    Times are the messages' header stamps [ns] on the robot's clock (sim time with
    ``/clock``); ``received`` wall times [s] (``time.perf_counter``) only measure latency.
    """

    def __init__(self, topic_map: TopicMap, robot: Robot) -> None:
        self.map, self.robot = topic_map, robot
        self.role = {topic: role for role, topic in topic_map.topics.items()}
        self.cond = threading.Condition()
        self.tf = TfBuffer(topic_map.world_frame)
        self.joints: dict[str, tuple[float, float, float]] = {}
        """Robot joint name -> (position, velocity, effort), the latest of any publisher."""
        self.joint_stamp: int | None = None
        """Stamp of the newest joint state once every robot joint has been heard [ns]."""
        self.color: deque[tuple[int, str, Any, float]] = deque(maxlen=KEEP)
        """(stamp, frame_id, message, received) of each colour image."""
        self.depth: deque[tuple[int, Any]] = deque(maxlen=KEEP)
        self.K: np.ndarray | None = None
        self.scans: deque[tuple[int, str, Any]] = deque(maxlen=KEEP)
        self.weights: deque[tuple[int, float]] = deque(maxlen=1000)
        self.poses: deque[tuple[int, Any]] = deque(maxlen=KEEP)
        """(stamp, PoseStamped) of a POI topic (``poi`` mapped as a topic)."""
        self.errors: list[str] = []
        """Messages that did not decode (the node stops on the first)."""

    def add(self, topic: str, msg: Any, received: float) -> None:
        """File one decoded message of ``topic`` and wake whoever waits."""
        with self.cond:
            try:
                self._add(topic, msg, received)
            except Exception as exc:  # a message the map's role cannot read: the node stops
                self.errors.append(f"{topic}: {exc}")
            self.cond.notify_all()

    def _add(self, topic: str, msg: Any, received: float) -> None:
        if topic in TF_TOPICS:
            self.tf.add(msg, static=topic == "/tf_static")
            self.tf.prune(KEEP)
            return
        role = self.role.get(topic)
        if role == "joint_states":
            self._joint_state(msg)
        elif role == "color":
            self.color.append((stamp_ns(msg.header.stamp), msg.header.frame_id, msg, received))
        elif role == "depth":
            self.depth.append((stamp_ns(msg.header.stamp), msg))
        elif role == "camera_info":
            k = msg.k if hasattr(msg, "k") else msg.K  # ROS 1 names it K
            self.K = np.array(k, dtype=float).reshape(3, 3)
        elif role == "lidar":
            self.scans.append((stamp_ns(msg.header.stamp), msg.header.frame_id, msg))
        elif role == "weight":
            self.weights.append((self.joint_stamp or 0, float(msg.data)))
        elif role == "poi":
            self.poses.append((stamp_ns(msg.header.stamp), msg))

    def _joint_state(self, msg: Any) -> None:
        """Merged by joint name across publishers (an arm's and its gripper's), renamed by
        the map's ``joints``; velocity and effort may be left empty."""
        n = len(msg.name)

        def column(values: Any) -> list[float]:
            return [float(v) for v in values] if len(values) == n else [0.0] * n

        pos, vel, eff = column(msg.position), column(msg.velocity), column(msg.effort)
        for i, name in enumerate(msg.name):
            self.joints[self.map.joints.get(name, name)] = (pos[i], vel[i], eff[i])
        if all(j in self.joints for j in self.robot.joint_names):
            t = stamp_ns(msg.header.stamp)
            self.joint_stamp = t if self.joint_stamp is None else max(t, self.joint_stamp)

    # --- readings (call with the lock held: inside ``with inbox.cond``) ----------------------

    def joint_state(self) -> JointState:
        """The robot's joints (``robot.joint_names`` order) at :attr:`joint_stamp`."""
        names = self.robot.joint_names
        p, v, e = (np.array([self.joints[n][k] for n in names]) for k in range(3))
        return JointState((self.joint_stamp or 0) / 1e9, names, p, v, e)

    def world(self, frame: str, t_ns: int) -> np.ndarray | None:
        """T_world_frame (4, 4) at ``t_ns``, None without a chain of transforms."""
        return self.tf.lookup(frame or self.map.world_frame, t_ns)

    def poi(self, t_ns: int) -> np.ndarray | None:
        """The POI ``[x, y, z, yaw]`` in the world frame: its TF frame at ``t_ns``, or the
        latest pose on its topic at or before it; None when there is none yet."""
        if self.map.poi_frame is not None:
            T = self.world(self.map.poi_frame, t_ns)
        else:
            msg = latest(list(self.poses), t_ns)
            if msg is None:
                return None
            W = self.world(msg.header.frame_id, stamp_ns(msg.header.stamp))
            if W is None:
                return None
            p, q = msg.pose.position, msg.pose.orientation
            T = np.eye(4)
            T[:3, :3] = quat_matrix([q.w, q.x, q.y, q.z])
            T[:3, 3] = [p.x, p.y, p.z]
            T = W @ T
        return None if T is None else np.array([*T[:3, 3], yaw_of(T[:3, :3])])

    def frame(self, t_ns: int) -> tuple[CameraFrame, float] | str:
        """The latest colour image at or before ``t_ns`` with its depth (stamped within
        20 ms), the camera info and the camera's pose at its stamp, and when it was
        received; or what is missing (one line)."""
        i = bisect.bisect_right([c[0] for c in self.color], t_ns) - 1
        if i < 0:
            return (
                f"no colour image on {self.map.topics['color']} at or before t={t_ns / 1e9:.3f} s"
            )
        stamp, frame_id, msg, received = self.color[i]
        depth = min(self.depth, key=lambda d: abs(d[0] - stamp), default=None)
        if depth is None or abs(depth[0] - stamp) > FRAME_MATCH_NS:
            depth_topic = self.map.topics.get("depth")
            return f"no depth image on {depth_topic} within 20 ms of t={stamp / 1e9:.3f} s"
        if self.K is None:
            return f"no camera info on {self.map.topics['camera_info']}"
        T = self.world(frame_id, stamp)
        if T is None:
            return f"no transform from {frame_id!r} to {self.map.world_frame!r} (tf_lost)"
        rgb = ros_rgb(msg, self.map.topics["color"])
        d = ros_depth(depth[1], rgb.shape[:2], self.map.depth_scale, self.map.topics["depth"])
        return CameraFrame(stamp / 1e9, rgb, d, self.K, T, frame_id), received

    def scan(self, t_ns: int) -> tuple[Scan2D, np.ndarray] | str:
        """The latest scan at or before ``t_ns`` in the lidar's frame and that frame's
        ``[x, y, yaw]`` in the world frame at its stamp; or what is missing."""
        i = bisect.bisect_right([s[0] for s in self.scans], t_ns) - 1
        if i < 0:
            return f"no scan on {self.map.topics.get('lidar')} at or before t={t_ns / 1e9:.3f} s"
        stamp, frame_id, msg = self.scans[i]
        T = self.world(frame_id, stamp)
        if T is None:
            return f"no transform from {frame_id!r} to {self.map.world_frame!r} (tf_lost)"
        ranges = np.array(msg.ranges, dtype=float)
        scan = Scan2D(
            ranges, float(msg.angle_min), float(msg.angle_increment), float(msg.range_max)
        )
        return scan, np.array([T[0, 3], T[1, 3], yaw_of(T[:3, :3])])

    def weight(self) -> float | None:
        return self.weights[-1][1] if self.weights else None

    def newest(self, role: str) -> int | None:
        """Stamp of the newest message of ``role`` [ns], None when none came."""
        series: dict[str, Callable[[], int | None]] = {
            "color": lambda: self.color[-1][0] if self.color else None,
            "depth": lambda: self.depth[-1][0] if self.depth else None,
            "lidar": lambda: self.scans[-1][0] if self.scans else None,
            "joint_states": lambda: self.joint_stamp,
            "poi": lambda: self.poses[-1][0] if self.poses else None,
        }
        return series[role]()
