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
"""

from __future__ import annotations

import bisect
import hashlib
import io
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from smccli.errors import LogError, SceneError
from smccli.logs import topics as tp
from smccli.logs.decode import unwrap_yaw
from smccli.logs.log import Log, PointCloudMsg, Scan
from smccli.schemas import validate_yaml
from smccli.world.geometry import quat_matrix, yaw_of
from smccli.world.sensors import CameraFrame, JointState, PoiCommand, SaliencyMark

ROLES: dict[str, tuple[str, tuple[str, ...]]] = {
    "command": (tp.COMMAND, ("geometry_msgs/msg/PoseStamped",)),
    "gripper_command": (tp.COMMAND, ("std_msgs/msg/Float64",)),
    "poi": (tp.POI, ("geometry_msgs/msg/PoseStamped",)),
    "joint_states": (tp.JOINT_STATES, ("sensor_msgs/msg/JointState",)),
    "color": (tp.COLOR, ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")),
    "depth": (tp.DEPTH, ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")),
    "camera_info": (tp.CALIBRATION, ("sensor_msgs/msg/CameraInfo",)),
    "weight": (tp.WEIGHT, ("std_msgs/msg/Float64",)),
    "lidar": (tp.SCAN, ("sensor_msgs/msg/LaserScan",)),
    "marks": (tp.SALIENCY, ("std_msgs/msg/String", "std_msgs/msg/Empty", "sensor_msgs/msg/Joy")),
    "points": (tp.POINTS, ("sensor_msgs/msg/PointCloud2",)),
}
"""Map role -> (the native topic it stands for, the ROS 2 types it may hold)."""
ROLE_OF = {native: role for role, (native, _) in reversed(ROLES.items())}
"""A native topic -> the map's role that stands for it (the first role listed)."""
TF_TOPICS = ("/tf", "/tf_static")
FRAME_MATCH_NS = 20_000_000
"""A depth image belongs to the colour image whose stamp is this close [ns] (20 ms)."""


@dataclass(frozen=True, slots=True)
class TopicMap:
    """A parsed, checked topic map."""

    path: Path | None
    """The map file, or None when built in code."""
    scene: str
    """The scene: a built-in name, or the path of a scene.yaml (resolved)."""
    world_frame: str
    """The fixed frame of poses and transforms."""
    topics: dict[str, str]
    """Role (``color``, ``poi``, ...) -> topic."""
    depth_scale: float = 0.001
    """Metres per unit of a 16UC1 depth image."""
    joints: dict[str, str] = field(default_factory=dict)
    """A driver's joint name -> the robot file's (``joints`` in the map)."""
    mark_button: int = 0
    """The button of a ``sensor_msgs/Joy`` marks topic whose press is a mark."""
    poi_frame: str | None = None
    """The POI as a TF frame (``poi: {frame: tool0}``) when no topic holds its pose."""


def parse_topic_map(data: dict[str, Any], path: Path | None = None) -> TopicMap:
    """A map from already schema-valid data (``schemas/topic_map.schema.json``)."""
    topics: dict[str, str] = {}
    scale, button, poi_frame = 0.001, 0, None
    for role, value in data["topics"].items():
        if isinstance(value, dict) and "frame" in value:  # the POI as a TF frame
            poi_frame = str(value["frame"]).lstrip("/")
        elif isinstance(value, dict):
            topics[role] = str(value["topic"])
            scale = float(value.get("scale", scale)) if role == "depth" else scale
            button = int(value.get("button", button)) if role == "marks" else button
        else:
            topics[role] = str(value)
    scene = str(data["scene"])
    if path is not None and (scene.endswith((".yaml", ".yml")) or "/" in scene):
        scene = str((path.parent / scene).resolve())
    joints = {str(k): str(v) for k, v in (data.get("joints") or {}).items()}
    world = str(data.get("world_frame", "world"))
    return TopicMap(path, scene, world, topics, scale, joints, button, poi_frame)


def load_topic_map(path: str | Path) -> TopicMap:
    """Read and check a topic map file; SceneError (one line: file, key, line) when bad,
    or when one topic is given two roles (a topic holds one signal)."""
    p = Path(path)
    try:
        text = p.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"{p}: cannot read topic map: {exc}") from None
    m = parse_topic_map(validate_yaml(text, "topic_map", str(p), SceneError), p)
    roles: dict[str, str] = {}
    for role, topic in m.topics.items():
        if topic in roles:
            raise SceneError(
                f"{p}: topics: {topic} is both the map's {roles[topic]} and its {role}; "
                "give each role its own topic (leave an optional one out)"
            )
        roles[topic] = role
    return m


# --- transforms --------------------------------------------------------------------------


class _TfBuffer:
    """Transforms parent -> child over time (``/tf``) and static (``/tf_static``); a frame's
    pose in the world frame at a time is the chain of the latest transforms up to it."""

    def __init__(self, world: str) -> None:
        self.world = world
        self._dynamic: dict[str, tuple[list[int], list[tuple[str, np.ndarray]]]] = {}
        self._static: dict[str, tuple[str, np.ndarray]] = {}

    def add(self, msg: Any, static: bool) -> None:
        for tr in msg.transforms:
            t, r = tr.transform.translation, tr.transform.rotation
            T = np.eye(4)
            T[:3, :3] = quat_matrix([r.w, r.x, r.y, r.z])
            T[:3, 3] = [t.x, t.y, t.z]
            parent = tr.header.frame_id.lstrip("/")
            child = tr.child_frame_id.lstrip("/")
            if static:
                self._static[child] = (parent, T)
            else:
                times, values = self._dynamic.setdefault(child, ([], []))
                times.append(_ns(tr.header.stamp))
                values.append((parent, T))

    def chain_times(self, frame: str) -> list[int]:
        """Every stamp [ns] at which a link between ``frame`` and the world frame moved."""
        times: set[int] = set()
        frame = frame.lstrip("/")
        for _ in range(32):
            if frame == self.world:
                break
            if frame in self._static:
                frame = self._static[frame][0]
            elif frame in self._dynamic:
                stamps, values = self._dynamic[frame]
                times.update(stamps)
                frame = values[-1][0]
            else:
                break
        return sorted(times)

    def lookup(self, frame: str, t_ns: int) -> np.ndarray | None:
        """T_world_frame at ``t_ns`` (the latest transform of each link at or before it, else
        the first one), or None when the chain does not reach the world frame."""
        T = np.eye(4)
        frame = frame.lstrip("/")
        for _ in range(32):
            if frame == self.world:
                return T
            if frame in self._static:
                parent, link = self._static[frame]
            elif frame in self._dynamic:
                times, values = self._dynamic[frame]
                i = max(bisect.bisect_right(times, t_ns) - 1, 0)
                parent, link = values[i]
            else:
                return None
            T = link @ T
            frame = parent
        return None


def _ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


# --- reading -----------------------------------------------------------------------------


def resolve_bag(path: str | Path) -> Path:
    """The file or directory to read a bag from: an MCAP file as it is; a bag directory
    as ``ros2 bag record`` writes it (``metadata.yaml`` and its storage files): its one
    ``.mcap`` file when it holds only that (the file is self-contained, and keeps the
    attachments of ``smc export``), else the directory (rosbag2 split into several files,
    or sqlite3 storage); a ROS 1 ``.bag``. LogError (one line) for anything else."""
    p = Path(path)
    if p.is_dir():
        parts = sorted(p.glob("*.mcap"))
        if len(parts) == 1 and not list(p.glob("*.db3")):
            return parts[0]
        if not (p / "metadata.yaml").is_file():
            found = ", ".join(q.name for q in sorted(p.iterdir())) or "nothing"
            raise LogError(f"{p}: a bag directory needs its metadata.yaml (rosbag2), found {found}")
        return p
    if not p.is_file():
        raise LogError(f"{p}: no such file")
    if p.suffix == ".db3":
        raise LogError(f"{p}: one file of a sqlite3 bag: give its directory (with metadata.yaml)")
    listed = _bag_files(p.parent)
    if p.suffix == ".mcap" and len(listed) > 1 and p.name in listed:
        raise LogError(
            f"{p}: one file of a bag split into {len(listed)}: give its directory {p.parent} "
            "(one demonstration)"
        )
    return p


def _bag_files(folder: Path) -> list[str]:
    """The storage files a rosbag2 directory's metadata.yaml lists (none without one)."""
    import yaml

    try:
        meta = yaml.safe_load((folder / "metadata.yaml").read_text())
        return [str(f) for f in meta["rosbag2_bagfile_information"]["relative_file_paths"]]
    except (OSError, yaml.YAMLError, KeyError, TypeError):
        return []


@dataclass
class BagSource:
    """A bag opened for reading: its topics and their types, message counts, smc's
    attachments and metadata (MCAP files only), its digest, and its messages decoded."""

    types: dict[str, str]
    """Topic -> message type (``sensor_msgs/msg/Image``)."""
    counts: dict[str, int]
    attachments: dict[str, bytes]
    metadata: dict[str, dict[str, str]]
    sha256: str
    start_ns: int
    """Log time of its first message [ns]."""
    end_ns: int
    """Log time of its last message [ns]."""
    messages: Callable[[list[str]], Iterator[tuple[str, int, Any]]]
    """Topics -> (topic, log time [ns], decoded message) in log-time order."""
    close: Callable[[], None] = lambda: None


def _open_mcap(path: Path) -> BagSource:
    """A ROS 2 bag in one MCAP file, decoded from the definitions it stores
    (``mcap-ros2-support``: it also gives the attachments ``smc export`` writes)."""
    data = path.read_bytes()
    try:
        reader = make_reader(io.BytesIO(data), decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        attachments = {a.name: bytes(a.data) for a in reader.iter_attachments()}
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    except (McapError, ValueError, EOFError, KeyError) as exc:
        raise LogError(f"{path}: not a readable MCAP file ({exc})") from None
    if summary is None or not summary.channels:
        raise LogError(f"{path}: the bag holds no topics")
    types = {}
    for c in summary.channels.values():
        schema = summary.schemas[c.schema_id]
        ros2 = schema.encoding == "ros2msg"
        types[c.topic] = schema.name if ros2 else f"{schema.name} ({schema.encoding}, not ROS 2)"
    counts: dict[str, int] = {}
    stats = summary.statistics
    if stats is not None:
        for cid, n in stats.channel_message_counts.items():
            counts[summary.channels[cid].topic] = n

    def messages(topics: list[str]) -> Iterator[tuple[str, int, Any]]:
        for _schema, channel, message, decoded in reader.iter_decoded_messages(
            topics=topics, log_time_order=True
        ):
            yield channel.topic, message.log_time, decoded

    sha = hashlib.sha256(data).hexdigest()
    t0, t1 = (stats.message_start_time, stats.message_end_time) if stats else (0, 0)
    return BagSource(types, counts, attachments, metadata, sha, t0, t1, messages)


def _open_rosbags(path: Path) -> BagSource:
    """A rosbag2 directory (sqlite3 or MCAP storage, any number of files) or a ROS 1 bag,
    read with ``rosbags``: messages decoded from the definitions the bag stores, else
    (a sqlite3 bag before Iron stores none) from ROS 2 Humble's standard types."""
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import Connection
    from rosbags.typesys import Stores, get_typestore

    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as exc:  # rosbags' own errors name the file's problem
        raise LogError(f"{path}: not a readable bag ({type(exc).__name__}: {exc})") from None
    conns: dict[str, list[Connection]] = {}
    for c in reader.connections:
        conns.setdefault(c.topic, []).append(c)
    if not conns:
        reader.close()
        raise LogError(f"{path}: the bag holds no topics")
    types = {t: cs[0].msgtype for t, cs in conns.items()}
    counts = {t: sum(c.msgcount for c in cs) for t, cs in conns.items()}
    files = [path] if path.is_file() else sorted(q for q in path.iterdir() if q.is_file())
    h = hashlib.sha256()
    for f in files:
        h.update(f.read_bytes())

    def messages(topics: list[str]) -> Iterator[tuple[str, int, Any]]:
        wanted = [c for t in topics for c in conns.get(t, [])]
        for conn, t_ns, raw in reader.messages(connections=wanted):
            try:
                msg = reader.deserialize(raw, conn.msgtype)
            except Exception as exc:  # a message its definition does not fit
                raise ValueError(f"{conn.topic}: {type(exc).__name__}: {exc}") from None
            yield conn.topic, t_ns, msg

    t0, t1 = reader.start_time, reader.end_time
    return BagSource(types, counts, {}, {}, h.hexdigest(), t0, t1, messages, reader.close)


def open_bag(path: Path) -> BagSource:
    """A bag resolved by :func:`resolve_bag`, opened: a rosbag2 directory or a ROS 1 bag
    through rosbags, an MCAP file through mcap-ros2-support. Close it when done."""
    return _open_rosbags(path) if path.is_dir() or path.suffix == ".bag" else _open_mcap(path)


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
    from smccli.world.scene import load_scene

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
        self.tf = _TfBuffer(m.world_frame)
        self.targets: list[tuple[float, np.ndarray]] = []
        self.grip: list[tuple[float, float]] = []
        self.joint_msgs: list[tuple[float, tuple[str, ...], np.ndarray, np.ndarray, np.ndarray]]
        self.joint_msgs = []  # (t, names, position, velocity, effort) of each message
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
            n = len(msg.name)
            names = tuple(self.map.joints.get(str(j), str(j)) for j in msg.name)

            def column(values: Any) -> np.ndarray:  # velocity and effort may be left empty
                return np.array(values, dtype=float) if len(values) == n else np.zeros(n)

            self.joint_msgs.append(
                (t, names, column(msg.position), column(msg.velocity), column(msg.effort))
            )
        elif role == "color":
            self.color.append((_ns(msg.header.stamp), msg.header.frame_id, msg))
        elif role == "depth":
            self.depth.append((_ns(msg.header.stamp), msg))
        elif role == "camera_info":
            k = msg.k if hasattr(msg, "k") else msg.K  # ROS 1 names it K
            self.info.append((_ns(msg.header.stamp), np.array(k, dtype=float).reshape(3, 3)))
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
        W = self.tf.lookup(frame, _ns(header.stamp))
        if W is None:
            raise LogError(
                f"{self.path}: {topic} at t={self.seconds(_ns(header.stamp)):.3f} s: no transform "
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
        from smccli.logs.topics import decode_color

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
            rgb = self._rgb(msg, decode_color)
            depth = self._depth(self.depth[i][1], rgb.shape[:2])
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

    def _rgb(self, msg: Any, decode_color: Callable[[bytes], np.ndarray | None]) -> np.ndarray:
        topic = self.map.topics["color"]
        if hasattr(msg, "format"):  # CompressedImage
            rgb = decode_color(bytes(msg.data))
            if rgb is None:
                raise LogError(
                    f"{self.path}: {topic}: image does not decode (format {msg.format!r})"
                )
            return rgb
        enc = msg.encoding.lower()
        if enc not in ("rgb8", "bgr8"):
            raise LogError(
                f"{self.path}: {topic}: encoding {msg.encoding!r}, expected rgb8 or bgr8"
            )
        img = _rows(msg, 3, np.uint8)
        return img[:, :, ::-1].copy() if enc == "bgr8" else img

    def _depth(self, msg: Any, shape: tuple[int, ...]) -> np.ndarray:
        topic = self.map.topics["depth"]
        if hasattr(msg, "format"):  # CompressedImage
            depth = compressed_depth(bytes(msg.data), msg.format, self.map.depth_scale)
            if isinstance(depth, str):
                raise LogError(f"{self.path}: {topic}: {depth}")
            if depth.shape != shape:
                raise LogError(
                    f"{self.path}: {topic}: depth {depth.shape[1]}x{depth.shape[0]} differs "
                    f"from the colour image's {shape[1]}x{shape[0]}"
                )
            return depth
        enc = msg.encoding.upper()
        if enc == "16UC1":
            img = _rows(msg, 1, np.dtype("<u2") if not msg.is_bigendian else np.dtype(">u2"))
            # In float64, then float32: for millimetres with scale 0.001 this equals the native
            # reader's mm / 1000 for every 16-bit value (float32 * 0.001 differs for 38850).
            depth = (img.astype(np.float64) * self.map.depth_scale).astype(np.float32)
        elif enc == "32FC1":
            img = _rows(msg, 1, np.dtype("<f4") if not msg.is_bigendian else np.dtype(">f4"))
            depth = np.nan_to_num(img.astype(np.float32), nan=0.0, posinf=0.0)
        else:
            raise LogError(
                f"{self.path}: {topic}: encoding {msg.encoding!r}, expected 16UC1 or 32FC1"
            )
        depth = depth.reshape(msg.height, msg.width)
        if depth.shape != shape:
            raise LogError(
                f"{self.path}: {topic}: depth {msg.width}x{msg.height} differs from the colour "
                f"image's {shape[1]}x{shape[0]}"
            )
        return depth


COMPRESSED_DEPTH_HEADER = struct.Struct("<iff")
"""image_transport's compressedDepth header before the PNG: the format (-1 undefined, 0
inverse depth) and the two quantisation parameters of a 32FC1 image's inverse depth."""


def compressed_depth(data: bytes, fmt: str, scale: float) -> np.ndarray | str:
    """A ``compressedDepth`` CompressedImage (image_transport's plugin, as RealSense users
    record depth) -> depth [m], float32 (h, w), 0 where there is none; or why it cannot be
    read (one line). 16UC1 is the PNG's values times ``scale``; 32FC1 is quantised inverse
    depth: depth = a / (v - b) for v > 0, a and b from the header."""
    import cv2

    kind = fmt.lower()
    if "compresseddepth" not in kind:
        return f"format {fmt!r}: a depth CompressedImage must be compressedDepth (PNG)"
    if "rvl" in kind:
        return (
            f"format {fmt!r}: compressedDepth RVL is not read; record with the plugin's "
            "format png, or republish the depth raw"
        )
    n = COMPRESSED_DEPTH_HEADER.size
    if len(data) <= n:
        return f"format {fmt!r}: {len(data)} bytes, no image after the {n}-byte header"
    _, a, b = COMPRESSED_DEPTH_HEADER.unpack(data[:n])
    img = cv2.imdecode(np.frombuffer(data[n:], dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None or img.dtype != np.uint16 or img.ndim != 2:
        return f"format {fmt!r}: the image after the header is not a 16-bit PNG"
    encoding = fmt.split(";")[0].strip().upper()
    if encoding == "16UC1":
        # In float64, then float32, as a raw 16UC1 image (the same values to the bit).
        return (img.astype(np.float64) * scale).astype(np.float32)
    if encoding == "32FC1":
        v = img.astype(np.float32)
        with np.errstate(divide="ignore"):
            depth = np.where(v > 0, np.float32(a) / (v - np.float32(b)), 0.0)
        return np.nan_to_num(depth.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    return f"format {fmt!r}: encoding {encoding!r}, expected 16UC1 or 32FC1"


def _rows(msg: Any, channels: int, dtype: Any) -> np.ndarray:
    """The pixels of a sensor_msgs/Image, rows of ``step`` bytes (padding dropped)."""
    dt = np.dtype(dtype)
    row = msg.width * channels * dt.itemsize
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(msg.height, msg.step)[:, :row]
    img = raw.copy().view(dt).reshape(msg.height, msg.width, channels)
    return img[:, :, 0] if channels == 1 else img
