"""Robots as data: an MJCF plus a robot file (YAML, ``schemas/robot.schema.json``).

The robot file says what the code must not hard-wire: the arm's joints, actuators and home
posture, the POI site, the gripper (joints, actuator, opening range), base joints if mobile,
the geom group of the robot's own geoms and the sensors mounted on it. The controller, the
simulation, the self-filter and the operators are built from a :class:`Robot`; no module
names a joint. Built-in robots live in ``smccli/world/robots/<name>/robot.yaml``; a scene
names its robot by name or by the path of a robot file.

A tree records the robot it was taught on by name and :func:`kinematics_digest`, a digest
of the kinematic chain from the robot's root to the POI (body offsets, joint axes and
limits), so a tree is never executed on a robot that moves differently.
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from smccli.errors import SceneError, SmcError
from smccli.schemas import YamlDocument, check_yaml, parse_yaml

ROBOTS_DIR = Path(__file__).parent / "robots"
DEFAULT_ROBOT = "arm"
"""The robot of scene files that name none (and of logs recorded before robot files)."""


@dataclass(frozen=True, slots=True)
class Gripper:
    """A parallel gripper driven by one position actuator."""

    joints: tuple[str, ...]
    """Finger joint names."""
    actuator: str
    """Its position actuator."""
    closed: float
    """Each finger joint's position when closed [m or rad]."""
    open: float
    """Each finger joint's position when fully open [m or rad]."""

    def target(self, opening: float) -> float:
        """Actuator target for an opening command in [0, 1] (0 closed, 1 open)."""
        return self.closed + float(np.clip(opening, 0.0, 1.0)) * (self.open - self.closed)

    def opening(self, q: np.ndarray) -> float:
        """Opening in [0, 1] from the finger joint positions ``q`` (mean over fingers)."""
        return float(np.clip((np.mean(q) - self.closed) / (self.open - self.closed), 0.0, 1.0))

    def opening_rate(self, qdot: np.ndarray) -> float:
        """Rate of change of :meth:`opening` from the finger joint speeds [1/s]."""
        return float(np.mean(qdot) / (self.open - self.closed))


@dataclass(frozen=True, slots=True)
class Base:
    """A mobile base: x slide, y slide, yaw hinge (docs/design.md 9)."""

    joints: tuple[str, str, str]
    actuators: tuple[str, str, str]


@dataclass(frozen=True, slots=True)
class SensorMount:
    """A sensor mounted on the robot."""

    name: str
    type: str
    """``camera`` or ``lidar``."""
    target: str
    """The MJCF camera (camera) or site (lidar) it is mounted at."""


@dataclass(frozen=True, slots=True)
class Robot:
    """A built-in or user robot: its file's text and what it declares."""

    name: str
    yaml_text: str
    """The robot file's text, verbatim (logs attach it as ``robot.yaml``)."""
    poi: str
    """The POI site."""
    arm_joints: tuple[str, ...] = ()
    """Arm joints, base to flange (empty: a mobile base without an arm)."""
    arm_actuators: tuple[str, ...] = ()
    """Their position actuators, same order."""
    home: tuple[float, ...] = ()
    """Home posture [rad], one per arm joint."""
    gripper: Gripper | None = None
    """The gripper (with an arm), else None."""
    base: Base | None = None
    geom_group: int = 3
    """MJCF geom group holding the robot's own geoms."""
    sensors: tuple[SensorMount, ...] = ()
    description: str = ""
    path: Path | None = None
    """The robot file, or None when rebuilt from a log's attachment."""
    mjcf_path: Path | None = None
    """The robot's MJCF file, or None when rebuilt from a log."""

    @property
    def dof(self) -> int:
        """Degrees of freedom the controller drives (arm, plus 3 for a mobile base)."""
        return len(self.arm_joints) + (3 if self.base else 0)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The joints a log's ``/robot/joint_states`` carries: base, arm, then fingers."""
        fingers = self.gripper.joints if self.gripper else ()
        return (self.base.joints if self.base else ()) + self.arm_joints + fingers

    def home_array(self) -> np.ndarray:
        """Home posture, shape (n_arm,) [rad]."""
        return np.array(self.home, dtype=float)


def builtin_robot_names() -> list[str]:
    """Names of the built-in robots."""
    return sorted(p.parent.name for p in ROBOTS_DIR.glob("*/robot.yaml"))


def list_robots() -> list[Robot]:
    """All built-in robots, each checked against its MJCF."""
    return [load_robot(n) for n in builtin_robot_names()]


def resolve_robot_path(ref: str, relative_to: Path | None = None) -> Path:
    """The robot file a scene's ``robot:`` names: a built-in name, or a path (relative to
    ``relative_to``, the scene file's folder)."""
    if ref in builtin_robot_names():
        return ROBOTS_DIR / ref / "robot.yaml"
    path = Path(ref)
    if not path.is_absolute() and relative_to is not None:
        path = Path(os.path.normpath(relative_to / path))  # names it as the user would
    if not path.is_file():
        raise SceneError(
            f"no robot {ref!r} (built-in robots: {', '.join(builtin_robot_names())}; "
            "or the path of a robot.yaml)"
        )
    return path


def load_robot(name_or_path: str | Path, relative_to: Path | None = None) -> Robot:
    """A built-in robot by name or a user robot by the path of its ``robot.yaml``, checked
    against its MJCF (compiled alone): SceneError naming the file and the key otherwise."""
    path = resolve_robot_path(str(name_or_path), relative_to)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"{path}: cannot read robot file: {exc}") from exc
    doc = _document(text, str(path), SceneError)
    mjcf = path.parent / str(doc.data.get("mjcf", "robot.xml"))
    if not mjcf.is_file():
        raise SceneError(f"{path}: {doc.where(('mjcf',))}: MJCF file {mjcf} not found")
    try:
        model = mujoco.MjModel.from_xml_path(str(mjcf))
    except ValueError as exc:
        raise SceneError(f"{mjcf}: MuJoCo rejects the MJCF: {' '.join(str(exc).split())}") from None
    robot = _robot(doc, text, path, mjcf)
    check_robot(robot, model, doc, mjcf.name, SceneError)
    _check_geom_group(robot, model, doc, mjcf.name)
    return robot


def robot_from_text(
    yaml_text: str, where: str, error_cls: type[SmcError] = SceneError
) -> tuple[Robot, YamlDocument]:
    """A robot from a robot file's text (a log's ``robot.yaml`` attachment), schema-checked
    but not yet checked against a model (:func:`check_robot`)."""
    doc = _document(yaml_text, where, error_cls)
    return _robot(doc, yaml_text, None, None), doc


def _document(text: str, where: str, error_cls: type[SmcError]) -> YamlDocument:
    doc = parse_yaml(text, where, error_cls)
    check_yaml(doc, "robot", error_cls)
    return doc


def _robot(doc: YamlDocument, text: str, path: Path | None, mjcf: Path | None) -> Robot:
    d: dict[str, Any] = doc.data
    arm, g, base = d.get("arm") or {}, d.get("gripper"), d.get("base")
    return Robot(
        name=str(d["name"]),
        yaml_text=text,
        arm_joints=tuple(str(j) for j in arm.get("joints", ())),
        arm_actuators=tuple(str(a) for a in arm.get("actuators", ())),
        home=tuple(float(v) for v in arm.get("home", ())),
        poi=str(d["poi"]),
        gripper=None
        if g is None
        else Gripper(
            joints=tuple(str(j) for j in g["joints"]),
            actuator=str(g["actuator"]),
            closed=float(g["opening"][0]),
            open=float(g["opening"][1]),
        ),
        base=Base(tuple(base["joints"]), tuple(base["actuators"])) if base else None,  # type: ignore[arg-type]
        geom_group=int(d.get("geom_group", 3)),
        sensors=tuple(
            SensorMount(str(s["name"]), str(s["type"]), str(s.get("camera") or s.get("site") or ""))
            for s in d.get("sensors") or ()
        ),
        description=str(d.get("description", "")),
        path=path,
        mjcf_path=mjcf,
    )


_KINDS = {
    "joint": mujoco.mjtObj.mjOBJ_JOINT,
    "actuator": mujoco.mjtObj.mjOBJ_ACTUATOR,
    "site": mujoco.mjtObj.mjOBJ_SITE,
    "camera": mujoco.mjtObj.mjOBJ_CAMERA,
}


def _names(model: mujoco.MjModel, kind: str) -> list[str]:
    count = {"joint": model.njnt, "actuator": model.nu, "site": model.nsite, "camera": model.ncam}
    obj = _KINDS[kind]
    return [n for i in range(count[kind]) if (n := mujoco.mj_id2name(model, obj, i))]


def check_robot(
    robot: Robot,
    model: mujoco.MjModel,
    doc: YamlDocument,
    mjcf_label: str,
    error_cls: type[SmcError],
) -> None:
    """Every name the robot file gives exists in ``model``, the arm has one actuator and one
    home value per joint, and home lies inside the joint limits; else one ``error_cls`` line
    naming the robot file, the key and the valid choices."""
    refs: list[tuple[tuple[str | int, ...], str, str]] = []
    refs += [(("arm", "joints", i), "joint", n) for i, n in enumerate(robot.arm_joints)]
    refs += [(("arm", "actuators", i), "actuator", n) for i, n in enumerate(robot.arm_actuators)]
    refs += [(("poi",), "site", robot.poi)]
    if robot.gripper:
        g = robot.gripper
        refs += [(("gripper", "joints", i), "joint", n) for i, n in enumerate(g.joints)]
        refs += [(("gripper", "actuator"), "actuator", g.actuator)]
    if robot.base:
        refs += [(("base", "joints", i), "joint", n) for i, n in enumerate(robot.base.joints)]
        refs += [
            (("base", "actuators", i), "actuator", n) for i, n in enumerate(robot.base.actuators)
        ]
    for i, s in enumerate(robot.sensors):
        kind = "camera" if s.type == "camera" else "site"
        refs.append((("sensors", i, kind), kind, s.target))
    for key, kind, name in refs:
        if mujoco.mj_name2id(model, _KINDS[kind], name) < 0:
            have = _names(model, kind)
            shown = ", ".join(have[:16]) + (", ..." if len(have) > 16 else "")
            raise error_cls(
                f"{doc.source}: {doc.where(key)}: no {kind} {name!r} in {mjcf_label} "
                f"({kind}s: {shown or 'none'})"
            )
    n = len(robot.arm_joints)
    for key, count in (
        (("arm", "actuators"), len(robot.arm_actuators)),
        (("arm", "home"), len(robot.home)),
    ):
        if count != n:
            raise error_cls(f"{doc.source}: {doc.where(key)}: {count} values for {n} arm joints")
    for i, (name, q) in enumerate(zip(robot.arm_joints, robot.home, strict=True)):
        j = model.joint(name).id
        lo, hi = model.jnt_range[j]
        if model.jnt_limited[j] and not lo - 1e-9 <= q <= hi + 1e-9:
            raise error_cls(
                f"{doc.source}: {doc.where(('arm', 'home', i))}: {q:g} rad is outside "
                f"{name}'s limits [{lo:g}, {hi:g}]"
            )
    if robot.gripper and robot.gripper.open == robot.gripper.closed:
        raise error_cls(
            f"{doc.source}: {doc.where(('gripper', 'opening'))}: closed and open are equal"
        )
    if robot.arm_joints:
        _check_axes(robot, model, doc, error_cls)


POINTS_DOWN = math.radians(15)
"""At home the POI's approach axis (its z) is at most this far from straight down [rad]."""
ALONG = math.radians(5)
"""The first joint's axis is this close to vertical, the last one's to the approach [rad]."""


def _check_axes(
    robot: Robot, model: mujoco.MjModel, doc: YamlDocument, error_cls: type[SmcError]
) -> None:
    """What the controller assumes of an arm (:mod:`smccli.world.controller`), at home:
    the gripper points down, the first joint turns about the upward vertical and the last
    rolls the gripper about its approach axis, in the approach's direction (so that the
    POI's yaw is q_first - q_last + a constant). A robot that breaks one reached its
    targets nowhere and said "out of reach"; here it gets the line that says what to fix."""
    data = mujoco.MjData(model)
    for name, q in zip(robot.arm_joints, robot.home, strict=True):
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = q
    mujoco.mj_kinematics(model, data)
    approach = data.site_xmat[model.site(robot.poi).id].reshape(3, 3)[:, 2]
    first, last = robot.arm_joints[0], robot.arm_joints[-1]
    first_axis = data.xaxis[model.joint(first).id]
    last_axis = data.xaxis[model.joint(last).id]

    def angle(a: np.ndarray, b: np.ndarray) -> float:
        return math.acos(max(-1.0, min(1.0, float(a @ b))))

    home = f"{doc.source}: {doc.where(('arm', 'home'))}"
    down = angle(approach, np.array([0.0, 0.0, -1.0]))
    if down > POINTS_DOWN:
        raise error_cls(
            f"{home}: at home the gripper's approach axis (the z of site {robot.poi!r}) points "
            f"{math.degrees(down):.0f} deg from straight down; give a home posture with the "
            "gripper pointing down, or turn the site so that its z leaves the fingers"
        )
    joints = f"{doc.source}: {doc.where(('arm', 'joints'))}"
    if angle(first_axis, np.array([0.0, 0.0, 1.0])) > ALONG:
        flip = " (flip its axis)" if first_axis[2] < 0 else ""
        raise error_cls(
            f"{joints}: the first joint {first!r} turns about [{_vec3(first_axis)}], not the "
            f"upward vertical{flip}: smc needs a base joint that turns the arm about +z"
        )
    roll = angle(last_axis, approach)
    if roll > ALONG:
        if math.pi - roll <= ALONG:
            raise error_cls(
                f"{joints}: the last joint {last!r} rolls the gripper the other way: its axis "
                f"at home is [{_vec3(last_axis)}], against the approach axis; flip the joint's "
                "axis (and mirror its range) so that it points out of the fingers"
            )
        raise error_cls(
            f"{joints}: the last joint {last!r} does not roll the gripper about its approach "
            f"axis (its axis at home is {math.degrees(roll):.0f} deg from it): list the arm's "
            "joints base to flange, ending with the wrist roll"
        )


def _vec3(v: np.ndarray) -> str:
    return ", ".join(f"{float(x) + 0.0:.2f}" for x in v)


def _check_geom_group(robot: Robot, model: mujoco.MjModel, doc: YamlDocument, label: str) -> None:
    """In the robot's own MJCF every geom is in ``geom_group`` (what lidar and self-filter
    rely on)."""
    for g in range(model.ngeom):
        if int(model.geom_group[g]) != robot.geom_group:
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"#{g}"
            raise SceneError(
                f"{doc.source}: {doc.where(('geom_group',))}: geom {name!r} of {label} is in "
                f"group {int(model.geom_group[g])}, not {robot.geom_group} (put every robot "
                "geom in one group)"
            )


def robot_geoms(robot: Robot, model: mujoco.MjModel) -> np.ndarray:
    """Ids of the robot's own geoms in a scene model: those of the bodies its joints move
    and of their ancestors up to the root, restricted to its geom group."""
    root = int(model.body_rootid[model.site_bodyid[model.site(robot.poi).id]])
    ids = [
        g
        for g in range(model.ngeom)
        if int(model.body_rootid[model.geom_bodyid[g]]) == root
        and int(model.geom_group[g]) == robot.geom_group
    ]
    return np.array(ids, dtype=int)


def kinematics_digest(robot: Robot, model: mujoco.MjModel) -> str:
    """``sha256:<hex>`` of the chain from the robot's root to the POI: each body's offset
    and orientation, its joints' types, axes, anchors and limits, the finger joints and the
    POI site's placement (rounded to 1 µm / 1e-6, so a flattened copy hashes the same)."""
    site = model.site(robot.poi).id
    chain = []
    b = int(model.site_bodyid[site])
    while b > 0:
        chain.append(b)
        b = int(model.body_parentid[b])
    rows: list[str] = []

    def fmt(values: Any) -> str:
        return " ".join(f"{float(v) + 0.0:.6f}" for v in np.ravel(values))

    for b in reversed(chain):
        rows.append(f"body {fmt(model.body_pos[b])} {fmt(model.body_quat[b])}")
        for j in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b]):
            rows.append(
                f"joint {int(model.jnt_type[j])} {fmt(model.jnt_axis[j])} {fmt(model.jnt_pos[j])}"
                f" {fmt(model.jnt_range[j])}"
            )
    for name in robot.gripper.joints if robot.gripper else ():
        j = model.joint(name).id
        rows.append(
            f"finger {int(model.jnt_type[j])} {fmt(model.jnt_axis[j])} {fmt(model.jnt_range[j])}"
        )
    rows.append(f"poi {fmt(model.site_pos[site])} {fmt(model.site_quat[site])}")
    rows.append("joints " + " ".join(robot.joint_names))
    return "sha256:" + hashlib.sha256("\n".join(rows).encode()).hexdigest()


def arm_reach(model: mujoco.MjModel, robot: Robot) -> tuple[np.ndarray, float]:
    """Where the arm's first joint's axis is and how far from it the POI can get: (anchor
    (3,) [m] world frame at the model's reference posture, radius [m]).

    The radius bounds the reach from the chain alone: the sum of the offsets from the first
    joint's anchor to the POI site (each body's offset from its parent, the site's from its
    body), which no posture can exceed. Sampling postures would give a tighter figure that
    may miss the stretched one; a crop box must not be too small.
    """
    first = model.joint(robot.arm_joints[0]).id
    top = int(model.jnt_bodyid[first])
    site = model.site(robot.poi).id
    radius = float(np.linalg.norm(model.site_pos[site]))
    b = int(model.site_bodyid[site])
    while b != top:
        if b <= 0:
            raise SceneError(f"robot {robot.name}: POI {robot.poi!r} is not below its first joint")
        radius += float(np.linalg.norm(model.body_pos[b]))
        b = int(model.body_parentid[b])
    radius += float(np.linalg.norm(model.jnt_pos[first]))
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    return data.xanchor[first].copy(), radius
