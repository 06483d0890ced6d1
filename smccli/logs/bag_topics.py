"""What a bag holds, for a person with a new bag (``smc topics BAG``): its topics with their
types, message counts and rates, what the first message of each says (an image's encoding,
a frame), its TF frames, and a draft topic map with the roles it can guess, written for the
user to check and complete (the scene line).

Guesses go by type first, then by name: an Image's encoding tells colour from depth, a
CompressedImage's format tells compressedDepth; among several candidates of one type the
name decides (``target``/``command`` is the teleoperation command, the camera info sharing
the colour topic's namespace is its). Without a pose topic the POI is a TF frame: a moving
leaf of the TF tree whose name says tool (``tool0``, ``*_tcp``, ``ee_link``, ...).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from smccli.logs.ros2_bag import TF_TOPICS, open_bag, resolve_bag

if TYPE_CHECKING:
    from smccli.world.robot import Robot


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """One topic of a bag."""

    topic: str
    type: str
    """ROS message type, e.g. ``sensor_msgs/msg/Image``."""
    count: int
    rate_hz: float
    """Messages per second of the bag's duration."""
    detail: str = ""
    """From its first message: an image's encoding or format, a message's frame."""


@dataclass(frozen=True, slots=True)
class BagContents:
    """A bag's topics and TF frames."""

    path: Path
    duration_s: float
    topics: tuple[TopicInfo, ...]
    frames: tuple[tuple[str, str, bool], ...]
    """TF links (parent, child, static) seen in ``/tf`` and ``/tf_static``."""
    pressed: dict[str, tuple[int, ...]]
    """A joystick topic -> the buttons pressed at least once in the bag."""
    joint_names: dict[str, tuple[str, ...]]
    """A JointState topic -> the joint names its messages carry (every publisher's)."""


_SAMPLE_TF = 2000
"""TF messages read for the frame list (a robot's whole tree is in its first few)."""


def bag_contents(path: str | Path) -> BagContents:
    """Read a bag's topics, counts, rates, first messages and TF frames (LogError, one
    line, for a bag that cannot be read)."""
    where = resolve_bag(path)
    src = open_bag(where)
    try:
        duration = max((src.end_ns - src.start_ns) / 1e9, 1e-9)
        details: dict[str, str] = {}
        names: dict[str, dict[str, None]] = {}
        links: dict[tuple[str, str], bool] = {}
        tf_seen = 0
        for topic, _t, msg in src.messages(sorted(src.types)):
            if topic in TF_TOPICS:
                tf_seen += 1
                for tr in msg.transforms:
                    key = (tr.header.frame_id.lstrip("/"), tr.child_frame_id.lstrip("/"))
                    links[key] = links.get(key, False) or topic == "/tf_static"
            else:
                details.setdefault(topic, _detail(msg))
                if src.types[topic] == "sensor_msgs/msg/JointState":
                    names.setdefault(topic, {}).update(dict.fromkeys(str(n) for n in msg.name))
            if len(details) >= len(src.types) - len(TF_TOPICS) and tf_seen >= _SAMPLE_TF:
                break
        joys = [t for t, kind in src.types.items() if kind == "sensor_msgs/msg/Joy"]
        pressed: dict[str, set[int]] = {t: set() for t in joys}
        for topic, _t, msg in src.messages(joys) if joys else ():
            pressed[topic].update(i for i, b in enumerate(msg.buttons) if b)
    finally:
        src.close()
    infos = tuple(
        TopicInfo(t, src.types[t], src.counts.get(t, 0), src.counts.get(t, 0) / duration, d)
        for t in sorted(src.types)
        for d in [details.get(t, "")]
    )
    frames = tuple((p, c, s) for (p, c), s in sorted(links.items()))
    buttons = {t: tuple(sorted(b)) for t, b in pressed.items()}
    joints = {t: tuple(n) for t, n in names.items()}
    return BagContents(Path(path), duration, infos, frames, buttons, joints)


def _detail(msg: Any) -> str:
    parts = []
    if hasattr(msg, "encoding"):
        parts.append(f"encoding {msg.encoding}")
    if hasattr(msg, "format"):
        parts.append(f"format {msg.format}")
    header = getattr(msg, "header", None)
    if header is not None and header.frame_id:
        parts.append(f"frame {header.frame_id}")
    if hasattr(msg, "name") and isinstance(msg.name, list):
        more = ", ..." if len(msg.name) > 4 else ""
        parts.append(f"{len(msg.name)} joints: {', '.join(msg.name[:4])}{more}")
    return "; ".join(parts)


# --- the draft map --------------------------------------------------------------------------

PLACEHOLDER_SCENE = "FILL_IN"
"""The draft map's scene: a bag does not say which scene (and robot) it was recorded in."""
_TOOL = re.compile(r"tool|tcp|ee(_|$)|end_?effector|flange|hand|gripper|grasp", re.IGNORECASE)
"""A TF frame named like a robot's tool."""
_COMMAND = re.compile(r"target|command|cmd|goal|teleop", re.IGNORECASE)
"""A pose topic named like a teleoperation command, not a measurement."""


def _of(c: BagContents, *types: str) -> list[TopicInfo]:
    return [t for t in c.topics if t.type in types and t.count > 0]


def _is_depth(t: TopicInfo) -> bool:
    d = t.detail.lower()
    return "compresseddepth" in d or "16uc1" in d or "32fc1" in d or "depth" in t.topic.lower()


def _namespace_match(a: str, b: str) -> int:
    """How many leading path components two topics share."""
    n = 0
    for x, y in zip(a.split("/"), b.split("/"), strict=False):
        if x != y:
            break
        n += 1
    return n


def draft_map(c: BagContents, robot: Robot | None = None) -> tuple[dict[str, Any], list[str]]:
    """A topic map (``schemas/topic_map.schema.json``) with the roles guessed from ``c``,
    and notes on what it could not tell (for the YAML's comments). With the scene's
    ``robot``, the driver's joint names are matched to the robot file's (``joints``)."""
    topics: dict[str, Any] = {}
    notes: list[str] = []
    images = _of(c, "sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
    colour = [t for t in images if not _is_depth(t)]
    depth = [t for t in images if _is_depth(t)]
    if colour:
        topics["color"] = min(colour, key=lambda t: ("color" not in t.topic, t.topic)).topic
    if depth:
        topics["depth"] = depth[0].topic
    infos = _of(c, "sensor_msgs/msg/CameraInfo")
    if infos:
        ref = topics.get("color", infos[0].topic)
        topics["camera_info"] = max(infos, key=lambda t: _namespace_match(t.topic, ref)).topic
    joints = _of(c, "sensor_msgs/msg/JointState")
    if joints:
        topics["joint_states"] = min(joints, key=lambda t: t.topic != "/joint_states").topic
    poses = _of(c, "geometry_msgs/msg/PoseStamped")
    commands = [t for t in poses if _COMMAND.search(t.topic)]
    measured = [t for t in poses if t not in commands]
    if commands:
        topics["command"] = commands[0].topic
    if measured:
        topics["poi"] = measured[0].topic
    else:
        tool = _tool_frame(c)
        if tool is not None:
            topics["poi"] = {"frame": tool}
            notes.append(f"poi: no pose topic; the TF frame {tool!r} is taken for the tool")
        else:
            notes.append("poi: no pose topic and no TF frame named like a tool: name one")
    for t in _of(c, "std_msgs/msg/Float64"):
        if re.search(r"grip", t.topic, re.IGNORECASE):
            topics.setdefault("gripper_command", t.topic)
        elif re.search(r"weight|scale|force", t.topic, re.IGNORECASE):
            topics.setdefault("weight", t.topic)
    for role, kind in (
        ("lidar", "sensor_msgs/msg/LaserScan"),
        ("points", "sensor_msgs/msg/PointCloud2"),
    ):
        found = _of(c, kind)
        if found:
            topics[role] = found[0].topic
    marks = _of(c, "std_msgs/msg/String", "std_msgs/msg/Empty", "sensor_msgs/msg/Joy")
    if marks:
        mark = min(marks, key=lambda t: not re.search(r"salien|mark|button|joy", t.topic, re.I))
        topics["marks"] = mark.topic
        if mark.type.endswith("/Joy"):
            used = c.pressed.get(mark.topic, ())
            topics["marks"] = {"topic": mark.topic, "button": used[0] if used else 0}
            if len(used) != 1:
                notes.append(
                    f"marks: buttons pressed on {mark.topic}: {list(used)}; set `button` to "
                    "the one the operator pressed at each salient moment"
                )
    renames: dict[str, str] = {}
    if joints and robot is None:
        notes.append(
            f"joint_states: the driver's names ({joints[0].detail}); if they differ from the "
            "robot file's, add `joints: {driver_name: robot_name, ...}` (or give --scene)"
        )
    elif joints and robot is not None:
        renames, unmatched = match_joints(c.joint_names.get(topics["joint_states"], ()), robot)
        if unmatched:
            notes.append(
                f"joints: {', '.join(unmatched)} match none of robot {robot.name!r}'s "
                f"({', '.join(robot.joint_names)}): map them by hand"
            )
    for role in ("color", "depth", "camera_info", "joint_states"):
        if role not in topics:
            notes.append(f"{role}: no topic of its type in the bag")
    data: dict[str, Any] = {"scene": PLACEHOLDER_SCENE, "world_frame": _world_frame(c)}
    if renames:
        data["joints"] = renames
    data["topics"] = topics
    return data, notes


def match_joints(driver: Sequence[str], robot: Robot) -> tuple[dict[str, str], list[str]]:
    """The driver's joint names matched to the robot file's: equal, or one ending with the
    other (``panda_joint1`` and ``joint1``), when exactly one robot joint fits. Returns the
    renames and the names no robot joint fits."""
    ours = robot.joint_names
    renames: dict[str, str] = {}
    unmatched: list[str] = []
    for name in driver:
        if name in ours:
            continue
        fits = [r for r in ours if name.endswith(r) or r.endswith(name)]
        if len(fits) == 1 and fits[0] not in renames.values():
            renames[name] = fits[0]
        else:
            unmatched.append(name)
    return renames, unmatched


def _tool_frame(c: BagContents) -> str | None:
    """A moving leaf of the TF tree named like a tool, the shortest such name first."""
    parents = {p for p, _, _ in c.frames}
    moving = {ch for _, ch, static in c.frames if not static}
    leaves = {ch for _, ch, _ in c.frames if ch not in parents}
    # A tool is often a fixed offset on a moving link: a leaf whose chain moves.
    parent_of = {ch: p for p, ch, _ in c.frames}

    def moves(frame: str) -> bool:
        for _ in range(32):
            if frame in moving:
                return True
            if frame not in parent_of:
                return False
            frame = parent_of[frame]
        return False

    tools = sorted((f for f in leaves if _TOOL.search(f) and moves(f)), key=lambda f: (len(f), f))
    return tools[0] if tools else None


def _world_frame(c: BagContents) -> str:
    """The TF tree's root (a frame that is nobody's child), ``world`` or ``map`` first."""
    children = {ch for _, ch, _ in c.frames}
    roots = sorted({p for p, _, _ in c.frames} - children)
    for name in ("world", "map", "odom"):
        if name in roots:
            return name
    return roots[0] if roots else "world"


def draft_map_text(c: BagContents, scene: str | None = None) -> str:
    """The draft map as YAML, with comments saying what to check; ``scene`` (a built-in
    name or a scene.yaml path) fills in the scene line and matches the joint names."""
    robot = None
    if scene is not None:
        from smccli.world.scene import load_scene

        robot = load_scene(scene).robot
    data, notes = draft_map(c, robot)
    if scene is not None:  # a path as the map will read it: relative to nothing
        path_like = scene.endswith((".yaml", ".yml")) or "/" in scene
        data["scene"] = str(Path(scene).resolve()) if path_like else scene
    head = [
        f"# Topic map drafted by `smc topics` from {c.path.name}: check every line.",
        "# scene: the scene the bag was recorded in, with its robot (a built-in name, or the",
        "# path of a scene.yaml relative to this file). Then: smc doctor BAG --topics MAP.",
        *(f"# note: {n}" for n in notes),
    ]
    return "\n".join(head) + "\n" + yaml.safe_dump(data, sort_keys=False)
