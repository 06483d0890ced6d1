"""ROS 2 bags in: a bag (MCAP storage, CDR messages) read into a :class:`~smccli.logs.Log`
through a topic map, so ``smc compile``, ``doctor`` and ``inspect`` take what real robots
record.

The map (``schemas/topic_map.schema.json``) says which topic is the colour image, the depth
and its scale, the camera info, the POI pose, the joints, the teleoperation command and
gripper command (optional: else the measured POI and the gripper's measured opening), the
weight, the lidar and the saliency marks. Frames come from ``/tf`` and ``/tf_static``:
every pose, image and scan is put in the map's ``world_frame`` at its own stamp. CDR is
decoded from the definitions stored in the bag (``mcap-ros2-support``: no ROS install).

A bag carries no scene: the map names it (the robot's model is needed for the
self-filter, the gripper and the sensors); a bag exported by ``smc export --ros2`` carries
the scene as attachments, which are used first.

The layers under it: the map (:mod:`~smccli.logs.topic_map`), opening a bag of any storage
(:mod:`~smccli.logs.bag_source`), transforms (:mod:`~smccli.logs.tf_buffer`), images and
depth (:mod:`~smccli.logs.ros2_images`); drafting a map for a new bag in
:mod:`~smccli.logs.bag_topics`.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from mcap.exceptions import McapError

from smccli.errors import LogError
from smccli.logs import topics as tp
from smccli.logs.bag_source import BagSource, open_bag, resolve_bag
from smccli.logs.decode import unwrap_yaw
from smccli.logs.log import Log, PointCloudMsg, Scan
from smccli.logs.ros2_images import compressed_depth, ros_depth, ros_rgb
from smccli.logs.tf_buffer import TF_TOPICS, TfBuffer, stamp_ns
from smccli.logs.topic_map import ROLE_OF, ROLES, TopicMap, load_topic_map, parse_topic_map
from smccli.world.geometry import quat_matrix, yaw_of
from smccli.world.sensors import CameraFrame, JointState, PoiCommand, SaliencyMark

__all__ = [  # the names compile, doctor and inspect import from here
    "ROLES",
    "ROLE_OF",
    "TF_TOPICS",
    "BagSource",
    "TopicMap",
    "compressed_depth",
    "load_topic_map",
    "open_bag",
    "parse_topic_map",
    "read_ros2_bag",
    "resolve_bag",
]

FRAME_MATCH_NS = 20_000_000
"""A depth image belongs to the colour image whose stamp is this close [ns] (20 ms)."""


def read_ros2_bag(
    path: str | Path,
    topic_map: TopicMap,
    *,
    on_warning: Callable[[str], None] | None = None,
) -> Log:
    """Read a bag through ``topic_map`` into a Log (times in seconds from the bag's first
    message; poses in the map's world frame): a ROS 2 bag in MCAP, a rosbag2 directory
    (sqlite3 or MCAP, split or not) or a ROS 1 bag.

    LogError (one line naming the file, and the topic) for a file that is not a readable
    bag, a mapped topic missing or holding another type, a pose without a transform to the
    world frame, an image that does not decode.
    """
    path = resolve_bag(path)
    src = open_bag(path)
    try:
        return _read(path, src, topic_map, on_warning or (lambda msg: None))
    finally:
        src.close()


def _read(path: Path, src: BagSource, topic_map: TopicMap, warn: Callable[[str], None]) -> Log:
    from smccli.world.scene import ASSET_PREFIX, load_scene

    types, counts, attachments, metadata = src.types, src.counts, src.attachments, src.metadata
    for role, topic in topic_map.topics.items():
        where = f"{path}: topic {topic} (the map's {role})"
        if topic not in types or counts.get(topic, 1) == 0:
            have = ", ".join(sorted(types)) or "none"
            raise LogError(f"{where} missing (topics in the bag: {have})")
        expected = ROLES[role][1]
        if types[topic] not in expected:
            raise LogError(f"{where} holds {types[topic]}, expected {' or '.join(expected)}")

    scene = load_scene(topic_map.scene)
    if "scene.yaml" not in attachments or "scene.xml" not in attachments:
        attachments = {
            "scene.yaml": scene.yaml_text.encode(),
            "scene.xml": scene.mjcf.encode(),
            "robot.yaml": scene.robot.yaml_text.encode(),
            **{f"{ASSET_PREFIX}{n}": b for n, b in scene.assets},
        }
    meta = metadata.get(tp.METADATA_NAME) or {
        "scene": scene.name,
        "scene_digest": scene.digest,
        "operator": "ros2",
        "has_scale": "true" if "weight" in topic_map.topics else "false",
    }

    b = _Builder(path, topic_map, scene.robot, warn, src.start_ns)
    wanted = [*topic_map.topics.values(), *(t for t in TF_TOPICS if t in types)]
    try:
        for topic, t_ns, decoded in src.messages(wanted):
            b.add(topic, t_ns, decoded)
    except (McapError, ValueError, EOFError) as exc:
        raise LogError(f"{path}: a message does not decode ({exc})") from None
    b.merge_joints()
    robot_joints = scene.robot.joint_names
    unknown = [n for n in (b.joints[0].names if b.joints else ()) if n not in robot_joints]
    if unknown:
        raise LogError(
            f"{path}: topic {topic_map.topics['joint_states']}: joint "
            f"{', '.join(unknown[:4])}{', ...' if len(unknown) > 4 else ''} not in robot "
            f"{scene.robot.name!r} ({', '.join(robot_joints)}); name the driver's joints "
            "with `joints:` in the topic map"
        )
    if topic_map.poi_frame is not None:
        b.poi_from_tf(topic_map.poi_frame)
    native_counts = {ROLES[r][0]: counts.get(t, 0) for r, t in topic_map.topics.items()}
    if "command" not in topic_map.topics:
        native_counts[tp.COMMAND] = len(b.poi)  # the measured POI is the demonstrated path
    native_counts[tp.TF] = sum(counts.get(t, 0) for t in TF_TOPICS)
    if topic_map.poi_frame is not None:
        native_counts[tp.POI] = len(b.poi)
    return Log(
        path=path,
        sha256=src.sha256,
        metadata={str(k): str(v) for k, v in meta.items()},
        attachments=attachments,
        commands=b.commands(),
        joint_states=b.joints,
        poi_t=np.array(b.poi_t, dtype=float),
        poi=unwrap_yaw(np.array(b.poi, dtype=float).reshape(-1, 4)),
        frames=b.frames(),
        weight_t=np.array(b.weight_t, dtype=float),
        weight=np.array(b.weight, dtype=float),
        marks=b.marks,
        ground_truth=[],
        decisions=[],
        topic_counts=native_counts,
        truncated=False,
        scans=b.scans,
        point_clouds=b.clouds,
        end=metadata.get(tp.END_METADATA_NAME, {}),
    )


class _Builder:
    """Collects the decoded messages of one bag, role by role."""

    def __init__(
        self, path: Path, m: TopicMap, robot: Any, warn: Callable[[str], None], origin_ns: int
    ) -> None:
        self.path, self.map, self.robot, self.warn = path, m, robot, warn
        self.origin = origin_ns
        """The bag's first message [ns]: a Log's times are seconds from it, as a person
        reads them (stamps stay absolute for the transforms)."""
        self.role = {topic: role for role, topic in m.topics.items()}
        self.tf = TfBuffer(m.world_frame)
        self.targets: list[tuple[float, np.ndarray]] = []
        self.grip: list[tuple[float, float]] = []
        self.joint_msgs: list[tuple[float, tuple[str, ...], np.ndarray, np.ndarray, np.ndarray]]
        self.joint_msgs = []  # (t, names, position, velocity, effort) of each message
        self.driver_of: dict[str, str] = {}
        """A robot joint -> the driver's name read as it."""
        self.names_seen: set[tuple[str, ...]] = set()
        self.joints: list[JointState] = []
        self.buttons_down = False
        self.poi_t: list[float] = []
        self.poi: list[np.ndarray] = []
        self.color: list[tuple[int, str, Any]] = []
        self.depth: list[tuple[int, Any]] = []
        self.info: list[tuple[int, np.ndarray]] = []
        self.weight_t: list[float] = []
        self.weight: list[float] = []
        self.marks: list[SaliencyMark] = []
        self.scans: list[Scan] = []
        self.clouds: list[PointCloudMsg] = []

    def add(self, topic: str, t_ns: int, msg: Any) -> None:
        if topic in TF_TOPICS:
            self.tf.add(msg, static=topic == "/tf_static")
            return
        role = self.role[topic]
        t = self.seconds(t_ns)
        if role in ("command", "poi"):
            pose = self._pose(topic, msg)
            if role == "command":
                self.targets.append((t, pose))
            else:
                self.poi_t.append(t)
                self.poi.append(pose)
        elif role == "gripper_command":
            self.grip.append((t, float(msg.data)))
        elif role == "joint_states":
            self._joint_state(t, msg)
        elif role == "color":
            self.color.append((stamp_ns(msg.header.stamp), msg.header.frame_id, msg))
        elif role == "depth":
            self.depth.append((stamp_ns(msg.header.stamp), msg))
        elif role == "camera_info":
            k = msg.k if hasattr(msg, "k") else msg.K  # ROS 1 names it K
            self.info.append((stamp_ns(msg.header.stamp), np.array(k, dtype=float).reshape(3, 3)))
        elif role == "weight":
            self.weight_t.append(t)
            self.weight.append(float(msg.data))
        elif role == "marks":
            if hasattr(msg, "buttons"):  # a joystick: a press (rising edge) is a mark
                i = self.map.mark_button
                down = i < len(msg.buttons) and bool(msg.buttons[i])
                if down and not self.buttons_down:
                    self.marks.append(SaliencyMark(t=t, source="operator", label=""))
                self.buttons_down = down
            else:
                label = getattr(msg, "data", "")
                self.marks.append(SaliencyMark(t=t, source="operator", label=label))
        elif role == "points":
            self.clouds.append(self._cloud(t, msg))
        elif role == "lidar":
            n = len(msg.ranges)
            end = msg.angle_min + msg.angle_increment * (n - 1)
            ranges = np.array(msg.ranges, dtype=float)
            self.scans.append(
                Scan(t, float(msg.angle_min), float(end), ranges, msg.header.frame_id)
            )

    def _joint_state(self, t: float, msg: Any) -> None:
        """A JointState, its names renamed by the map's ``joints``; LogError when two of the
        driver's names read as one robot joint (a name the map gives another joint)."""
        n = len(msg.name)
        driver = tuple(str(j) for j in msg.name)
        names = tuple(self.map.joints.get(j, j) for j in driver)
        if driver not in self.names_seen:
            self.names_seen.add(driver)
            for d, ours in zip(driver, names, strict=True):
                first = self.driver_of.setdefault(ours, d)
                if first != d:
                    raise LogError(
                        f"{self.path}: topic {self.map.topics['joint_states']}: joints {first} "
                        f"and {d} both read as robot joint {ours} (`joints:` in "
                        f"{self.map.path or 'the topic map'}); map one driver joint to each"
                    )

        def column(values: Any) -> np.ndarray:  # velocity and effort may be left empty
            return np.array(values, dtype=float) if len(values) == n else np.zeros(n)

        self.joint_msgs.append(
            (t, names, column(msg.position), column(msg.velocity), column(msg.effort))
        )

    def seconds(self, t_ns: int) -> float:
        """A time of the bag [ns] in seconds from its first message."""
        return (t_ns - self.origin) / 1e9

    def poi_from_tf(self, frame: str) -> None:
        """The POI as the TF frame ``frame`` in the world frame, ``[x, y, z, yaw]``, at each
        stamp a link of its chain moved (a UR driver publishes no pose, only TF)."""
        for t_ns in self.tf.chain_times(frame):
            T = self.tf.lookup(frame, t_ns)
            if T is not None:
                self.poi_t.append(self.seconds(t_ns))
                self.poi.append(np.array([*T[:3, 3], yaw_of(T[:3, :3])]))
        if not self.poi:
            raise LogError(
                f"{self.path}: POI frame {frame!r}: no transforms from it to "
                f"{self.map.world_frame!r} that move in /tf"
            )

    def merge_joints(self) -> None:
        """Joint states from every publisher on the topic (an arm's driver and a separate
        gripper's, say) merged by joint name: from the first time every joint has been
        heard, each message gives the state of all of them, the others at their latest
        values. One publisher's states come out as they went in."""
        order: dict[str, int] = {}
        for _, names, *_ in self.joint_msgs:
            for n in names:
                order.setdefault(n, len(order))
        k = len(order)
        pos, vel, eff = np.zeros(k), np.zeros(k), np.zeros(k)
        heard = np.zeros(k, dtype=bool)
        all_names = tuple(order)
        for t, names, p, v, e in self.joint_msgs:
            idx = [order[n] for n in names]
            pos[idx], vel[idx], eff[idx], heard[idx] = p, v, e, True
            if heard.all():
                self.joints.append(JointState(t, all_names, pos.copy(), vel.copy(), eff.copy()))

    def _world(self, topic: str, header: Any) -> np.ndarray:
        """T_world_frame of a message's ``header`` (frame and stamp); LogError without a
        chain of transforms to the world frame."""
        frame = header.frame_id or self.map.world_frame
        t_ns = stamp_ns(header.stamp)
        W = self.tf.lookup(frame, t_ns)
        if W is None:
            raise LogError(
                f"{self.path}: {topic} at t={self.seconds(t_ns):.3f} s: no transform "
                f"from frame {frame!r} to {self.map.world_frame!r} in /tf or /tf_static"
            )
        return W

    def _pose(self, topic: str, msg: Any) -> np.ndarray:
        """A PoseStamped as ``[x, y, z, yaw]`` in the world frame."""
        p, q = msg.pose.position, msg.pose.orientation
        T = np.eye(4)
        T[:3, :3] = quat_matrix([q.w, q.x, q.y, q.z])
        T[:3, 3] = [p.x, p.y, p.z]
        T = self._world(topic, msg.header) @ T
        return np.array([*T[:3, 3], yaw_of(T[:3, :3])])

    def _cloud(self, t: float, msg: Any) -> PointCloudMsg:
        """A PointCloud2's x, y, z (FLOAT32) and packed ``rgb``, moved into the world frame."""
        fields = {f.name: f for f in msg.fields}
        topic = self.map.topics["points"]
        if any(k not in fields or fields[k].datatype != 7 for k in "xyz"):
            raise LogError(f"{self.path}: {topic}: expected FLOAT32 fields x, y, z")
        n = msg.width * msg.height
        raw = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(n, msg.point_step)
        endian = ">" if msg.is_bigendian else "<"

        def column(name: str, kind: str) -> np.ndarray:
            off = fields[name].offset
            return raw[:, off : off + 4].copy().view(endian + kind).reshape(n)

        xyz = np.stack([column(k, "f4") for k in "xyz"], axis=1).astype(np.float64)
        ok = np.isfinite(xyz).all(axis=1)
        colors = None
        if "rgb" in fields:
            packed = column("rgb", "u4")[ok]
            colors = np.stack([(packed >> s) & 0xFF for s in (16, 8, 0)], axis=1).astype(np.uint8)
        W = self._world(topic, msg.header)
        pts = (xyz[ok] @ W[:3, :3].T + W[:3, 3]).astype(np.float32)
        return PointCloudMsg(t, pts, colors, self.map.world_frame)

    def commands(self) -> list[PoiCommand]:
        """The teleoperation commands; without a command topic, the measured POI (and the
        gripper's measured opening, without a gripper command topic)."""
        targets = self.targets or list(zip(self.poi_t, self.poi, strict=True))
        g_t = np.array([t for t, _ in self.grip])
        g_v = [v for _, v in self.grip]
        j_t = np.array([j.t for j in self.joints])
        out = []
        for t, target in targets:
            if len(g_t):
                i = max(int(np.searchsorted(g_t, t + 1e-9)) - 1, 0)
                grip = g_v[i]
            else:
                grip = self._opening(j_t, t)
            out.append(PoiCommand(t=t, target=np.asarray(target, dtype=float), gripper=grip))
        return out

    def _opening(self, j_t: np.ndarray, t: float) -> float:
        """The gripper's measured opening in [0, 1] at ``t`` (1 without a gripper)."""
        g = self.robot.gripper
        if g is None or not len(j_t):
            return 1.0
        js = self.joints[max(int(np.searchsorted(j_t, t + 1e-9)) - 1, 0)]
        idx = [js.names.index(n) for n in g.joints if n in js.names]
        if len(idx) != len(g.joints):
            return 1.0
        return float(g.opening(js.position[idx]))

    def frames(self) -> list[CameraFrame]:
        """Colour images joined with the depth of the same stamp, the latest camera info
        and the camera's pose from the transforms."""
        depth_t = np.array([t for t, _ in self.depth], dtype=np.int64)
        info_t = [t for t, _ in self.info]
        out: list[CameraFrame] = []
        no_depth, no_info, no_tf, untransformed = 0, 0, 0, set()
        for t_ns, frame_id, msg in self.color:
            i = int(np.argmin(np.abs(depth_t - t_ns))) if len(depth_t) else -1
            k = bisect.bisect_right(info_t, t_ns) - 1
            T = self.tf.lookup(frame_id, t_ns)
            lacks_depth = i < 0 or abs(int(depth_t[i]) - t_ns) > FRAME_MATCH_NS
            no_depth += lacks_depth
            no_info += not self.info
            if T is None:
                no_tf += 1
                untransformed.add(frame_id or "''")
            if lacks_depth or not self.info or T is None:
                continue
            rgb = ros_rgb(msg, f"{self.path}: {self.map.topics['color']}")
            where = f"{self.path}: {self.map.topics['depth']}"
            depth = ros_depth(self.depth[i][1], rgb.shape[:2], self.map.depth_scale, where)
            K = self.info[max(k, 0)][1]
            out.append(CameraFrame(self.seconds(t_ns), rgb, depth, K, T, frame_id))
        why = []
        if no_depth:
            topic = self.map.topics.get("depth", "(no depth topic mapped)")
            why.append(f"{no_depth} lack a depth image on {topic} within 20 ms")
        if no_info:
            why.append(f"{no_info} lack camera info on {self.map.topics['camera_info']}")
        if no_tf:
            frames = ", ".join(sorted(untransformed))
            why.append(
                f"{no_tf} lack a transform from frame {frames} to {self.map.world_frame!r} "
                "in /tf or /tf_static"
            )
        if why:
            n, color = len(self.color), self.map.topics["color"]
            self.warn(
                f"{self.path}: {n - len(out)} of {n} colour images on {color} are left out: "
                + "; ".join(why)
            )
        return out
