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
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from smccli.logs.bag_source import open_bag, resolve_bag
from smccli.logs.tf_buffer import TF_TOPICS

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


@dataclass(frozen=True, slots=True)
class Draft:
    """A drafted topic map and what is left for the user before it reads the bag."""

    bag: str
    """The bag's file or directory name."""
    data: dict[str, Any]
    """The map (``schemas/topic_map.schema.json``); its scene :data:`PLACEHOLDER_SCENE`
    when none was given."""
    notes: tuple[str, ...]
    """What the draft could not tell, one line each (the YAML's comments)."""
    unmatched: tuple[str, ...] = ()
    """Driver joint names left for the user (matched against a scene's robot only)."""

    @property
    def scene_filled(self) -> bool:
        return self.data["scene"] != PLACEHOLDER_SCENE

    def todo(self) -> tuple[str, ...]:
        """What the user has left to do, in order (checking each guessed role always)."""
        out = [] if self.scene_filled else ["fill in its scene"]
        if self.unmatched:
            out.append(f"map the joints {', '.join(self.unmatched)} by hand")
        return (*out, "check each role")

    def text(self) -> str:
        """The map as YAML, with comments saying what to check."""
        head = [
            f"# Topic map drafted by `smc topics` from {self.bag}: check every line.",
            "# scene: the scene the bag was recorded in, with its robot (a built-in name, or the",
            "# path of a scene.yaml relative to this file). Then: smc doctor BAG --topics MAP.",
            "# To run a tree on the robot (smc run --ros1) add a run: section: run.command",
            "# (PoseStamped) or run.arm (JointTrajectory), run.gripper: docs/on_a_robot.md.",
            *(f"# note: {n}" for n in self.notes),
        ]
        return "\n".join(head) + "\n" + yaml.safe_dump(self.data, sort_keys=False)


def draft_map(c: BagContents, robot: Robot | None = None) -> Draft:
    """A topic map with the roles guessed from ``c``, and notes on what it could not tell.
    With the scene's ``robot``, the driver's joint names are matched to the robot file's
    (``joints``, :func:`match_joints`)."""
    topics: dict[str, Any] = _camera_roles(c)
    joints = _of(c, "sensor_msgs/msg/JointState")
    if joints:
        topics["joint_states"] = _joint_topic(c, joints).topic
    poses, notes = _pose_roles(c)
    others, other_notes = _other_roles(c)
    topics.update(poses)
    topics.update(others)
    notes += other_notes
    data: dict[str, Any] = {"scene": PLACEHOLDER_SCENE, "world_frame": _world_frame(c)}
    renames, joint_notes, unmatched = _joint_draft(c, joints, robot)
    notes += joint_notes
    if renames:
        data["joints"] = renames
    for role in ("color", "depth", "camera_info", "joint_states"):
        if role not in topics:
            notes.append(f"{role}: no topic of its type in the bag")
    data["topics"] = topics
    return Draft(c.path.name, data, tuple(notes), unmatched)


def _camera_roles(c: BagContents) -> dict[str, Any]:
    """``color``, ``depth`` (an image's encoding or format, else its name, says depth) and
    ``camera_info`` (the one sharing most of the colour topic's namespace)."""
    topics: dict[str, Any] = {}
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
    return topics


def _pose_roles(c: BagContents) -> tuple[dict[str, Any], list[str]]:
    """``command`` (a pose topic named like one) and ``poi`` (another pose topic, else a
    TF frame named like a tool), with notes."""
    topics: dict[str, Any] = {}
    notes: list[str] = []
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
    return topics, notes


def _other_roles(c: BagContents) -> tuple[dict[str, Any], list[str]]:
    """``gripper_command``, ``weight``, ``lidar``, ``points`` and ``marks`` (a Joy's button
    when one was pressed), with notes."""
    topics: dict[str, Any] = {}
    notes: list[str] = []
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
    return topics, notes


def _joint_topic(c: BagContents, joints: list[TopicInfo]) -> TopicInfo:
    """The JointState topic the map reads: ``/joint_states``, else the one with the most
    joints (an arm's rather than its gripper's), else the first by name."""

    def rank(t: TopicInfo) -> tuple[bool, int]:
        return t.topic != "/joint_states", -len(c.joint_names.get(t.topic, ()))

    return min(joints, key=rank)


def _joint_draft(
    c: BagContents, joints: list[TopicInfo], robot: Robot | None
) -> tuple[dict[str, str], list[str], tuple[str, ...]]:
    """The driver's names renamed to ``robot``'s, notes, and the names left for the user."""
    notes: list[str] = []
    if len(joints) > 1:
        notes.append(
            f"joint_states: {len(joints)} JointState topics "
            f"({', '.join(t.topic for t in joints)}); the map reads "
            f"{_joint_topic(c, joints).topic} only (an arm's "
            "and a gripper's publishers are merged when they share a topic)"
        )
    if not joints:
        return {}, notes, ()
    if robot is None:
        notes.append(
            f"joint_states: the driver's names ({joints[0].detail}); if they differ from the "
            "robot file's, add `joints: {driver_name: robot_name, ...}` (or give --scene)"
        )
        return {}, notes, ()
    # Every JointState topic's names: a gripper publishing on its own topic is still the
    # robot's, and its names may fit the arm's joints too.
    driver = dict.fromkeys(n for t in joints for n in c.joint_names.get(t.topic, ()))
    match = match_joints(tuple(driver), robot)
    return match.renames, notes + match.notes(robot), match.unmatched


@dataclass(frozen=True, slots=True)
class JointMatch:
    """The driver's joint names matched to a robot file's."""

    renames: dict[str, str]
    """A driver name -> the robot's, where that robot joint is the only one that fits the
    driver's and the driver's is the only one that fits it."""
    unfit: tuple[str, ...]
    """Driver names no robot joint fits."""
    shared: dict[str, tuple[str, ...]]
    """A robot joint -> the driver names that all fit it (none of them renamed)."""
    several: dict[str, tuple[str, ...]]
    """A driver name -> the robot joints that all fit it (not renamed)."""

    unmatched: tuple[str, ...]
    """Every driver name left for the user (of the three kinds above), in the driver's
    order."""

    def notes(self, robot: Robot) -> list[str]:
        """One line per kind of name left for the user, for the draft's comments."""
        out = [
            f"joints: {', '.join(ds)} all fit robot joint {r}: map the right one by hand"
            for r, ds in self.shared.items()
        ]
        out += [
            f"joints: {d} fits robot joints {', '.join(rs)}: map it by hand"
            for d, rs in self.several.items()
        ]
        if self.unfit:
            out.append(
                f"joints: {', '.join(self.unfit)} match none of robot {robot.name!r}'s "
                f"({', '.join(robot.joint_names)}): map them by hand"
            )
        return out


def match_joints(driver: Sequence[str], robot: Robot) -> JointMatch:
    """The driver's joint names matched to the robot file's. A driver name fits a robot
    joint of the same name, else one it ends with or that ends with it (``panda_joint1``
    and ``joint1``); it is renamed only when exactly one fits, each way: a robot joint two
    driver names fit (``panda_joint1`` and ``panda_finger_joint1`` both end with
    ``joint1``) is left for the user, as is a driver name that fits two."""
    ours = robot.joint_names
    fits: dict[str, list[str]] = {}
    for name in dict.fromkeys(driver):
        fits[name] = (
            [name] if name in ours else [r for r in ours if name.endswith(r) or r.endswith(name)]
        )
    fitted_by: dict[str, list[str]] = {}
    for name, rs in fits.items():
        for r in rs:
            fitted_by.setdefault(r, []).append(name)
    renames: dict[str, str] = {}
    for name, rs in fits.items():
        if len(rs) == 1 and len(fitted_by[rs[0]]) == 1 and rs[0] != name:
            renames[name] = rs[0]
    shared = {r: tuple(ds) for r, ds in fitted_by.items() if len(ds) > 1}
    in_shared = {d for ds in shared.values() for d in ds}
    return JointMatch(
        renames=renames,
        unfit=tuple(n for n, rs in fits.items() if not rs),
        shared=shared,
        several={n: tuple(rs) for n, rs in fits.items() if len(rs) > 1},
        unmatched=tuple(n for n, rs in fits.items() if len(rs) != 1 or n in in_shared),
    )


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


def draft_topic_map(c: BagContents, scene: str | None = None) -> Draft:
    """The draft map of ``c``; ``scene`` (a built-in name or a scene.yaml path) fills in
    the scene line and matches the joint names to its robot's."""
    robot = None
    if scene is not None:
        from smccli.world.scene import load_scene

        robot = load_scene(scene).robot
    draft = draft_map(c, robot)
    if scene is not None:  # a path as the map will read it: relative to nothing
        path_like = scene.endswith((".yaml", ".yml")) or "/" in scene
        filled = str(Path(scene).resolve()) if path_like else scene
        draft = replace(draft, data={**draft.data, "scene": filled})
    return draft


def draft_map_text(c: BagContents, scene: str | None = None) -> str:
    """The draft map of ``c`` as YAML with its comments (:func:`draft_topic_map`)."""
    return draft_topic_map(c, scene).text()
