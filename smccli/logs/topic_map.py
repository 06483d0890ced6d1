"""Topic maps: which topics of a bag hold what smc perceives and learns from
(``schemas/topic_map.schema.json``), parsed and checked."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from smccli.errors import SceneError
from smccli.logs import topics as tp
from smccli.schemas import validate_yaml

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


@dataclass(frozen=True, slots=True)
class RunSpec:
    """The map's ``run`` section: how ``smc run --ros1`` commands the robot and when it
    stops it (``schemas/topic_map.schema.json``)."""

    command: str | None
    """geometry_msgs/PoseStamped topic of the POI's target (None: ``arm``)."""
    arm: str | None = None
    """trajectory_msgs/JointTrajectory topic of the arm's joint targets (None: ``command``)."""
    gripper: str | None = None
    """trajectory_msgs/JointTrajectory topic of the gripper's fingers (None: not commanded)."""
    stale_s: float = 0.5
    """A needed sensor whose newest stamp is older than this (robot clock), and still so
    after ``wait_s``, stops it [s]."""
    wait_s: float = 5.0
    """Longest wall-clock wait for the next joint state or a fresh image [s]."""
    period_s: float = 0.01
    """Control period [s]."""


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
    run: RunSpec | None = None
    """The ``run`` section (``smc run --ros1``), None when the map has none."""


def parse_topic_map(data: dict[str, Any], path: Path | None = None) -> TopicMap:
    """A map from already schema-valid data (``schemas/topic_map.schema.json``); SceneError
    (one line) when ``joints`` sends two driver joints to one robot joint."""
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
    _check_joints(joints, path)
    world = str(data.get("world_frame", "world"))
    run = None
    if (r := data.get("run")) is not None:
        command, arm, gripper = (
            None if r.get(k) is None else _topic(r[k]) for k in ("command", "arm", "gripper")
        )
        times = {k: float(r[k]) for k in ("stale_s", "wait_s", "period_s") if k in r}
        run = RunSpec(command, arm, gripper, **times)
    return TopicMap(path, scene, world, topics, scale, joints, button, poi_frame, run)


def _topic(value: Any) -> str:
    """A ``$defs/topic`` value: the name, or a mapping holding it."""
    return str(value["topic"] if isinstance(value, dict) else value)


def _check_joints(joints: dict[str, str], path: Path | None) -> None:
    """Each robot joint renamed from one driver joint at most: two merged into one would
    give that joint both drivers' states, a tree of another robot."""
    driver_of: dict[str, str] = {}
    for driver, ours in joints.items():
        if ours in driver_of:
            raise SceneError(
                f"{path or 'topic map'}: joints: {driver_of[ours]} and {driver} both map to "
                f"robot joint {ours}; map one driver joint to each robot joint"
            )
        driver_of[ours] = driver


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
