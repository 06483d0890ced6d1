"""Robots as data: an MJCF plus a robot file (YAML, ``schemas/robot.schema.json``).

The robot file says what the code must not hard-wire: the arm's joints, actuators and home
posture, the POI site, the gripper (joints, actuator, opening range), base joints if mobile
and the sensors mounted on it. It names the vendor's files as they are: the arm's ``mjcf:``
or ``urdf:``, a gripper's own ``mjcf:`` attached to the arm; :mod:`smccli.world.robot_compose`
composes them (without a gripper file, servos or a URDF, the arm's MJCF is used as written).
Which geoms are the robot's is read from the model (the bodies under its root);
``geom_group`` narrows them to one group where an older robot file gives it. The controller, the
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
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from smccli.errors import SceneError, SmcError
from smccli.schemas import YamlDocument, check_yaml, parse_yaml
from smccli.world.robot_compose import (
    POI_SITE,
    SERVO_PREFIX,
    Composition,
    GripperFile,
    PoiPlacement,
    Servo,
    frame_of,
    robot_spec,
)

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
    commands: tuple[float, float] | None = None
    """The actuator's command when closed and when open, in its own units (a tendon
    actuator's 0-255, ...); None: the joint positions :attr:`closed`, :attr:`open`."""

    def target(self, opening: float) -> float:
        """Actuator command for an opening in [0, 1] (0 closed, 1 open)."""
        closed, open_ = self.commands or (self.closed, self.open)
        # np.clip's value on a Python float (NaN stays NaN), at a tenth of its cost: this
        # runs every control period.
        o = float(opening)
        o = 0.0 if o < 0.0 else 1.0 if o > 1.0 else o
        return closed + o * (open_ - closed)

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
    geom_group: int | None = None
    """The geom group of the robot's own geoms where the robot file gives one (older files:
    every robot geom in it); None: the robot's geoms are those of its bodies, in whatever
    groups the model puts them (:func:`robot_geoms`)."""
    sensors: tuple[SensorMount, ...] = ()
    description: str = ""
    path: Path | None = None
    """The robot file, or None when rebuilt from a log's attachment."""
    mjcf_path: Path | None = None
    """The robot's MJCF (or the arm's MJCF or URDF when composed), or None when rebuilt from
    a log."""
    composition: Composition | None = None
    """What smc composes (a gripper file, servos, a URDF, a POI site, a mount); None: the
    MJCF is used as written (included in the scene)."""

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
    key = "urdf" if "urdf" in doc.data else "mjcf"
    mjcf = path.parent / str(doc.data.get(key, "robot.xml"))
    files: list[tuple[tuple[str, ...], Path]] = [((key,), mjcf)]
    if "mjcf" in (doc.data.get("gripper") or {}):
        files.append((("gripper", "mjcf"), path.parent / str(doc.data["gripper"]["mjcf"])))
    for at, file in files:
        if not file.is_file():
            what = "MJCF file" if file.suffix.lower() == ".xml" else "file"
            raise SceneError(f"{path}: {doc.where(at)}: {what} {file} not found")
    robot = _robot(doc, text, path, mjcf)
    if robot.composition is None and _names_files(mjcf):
        # Composed, its files' paths are made absolute from its own folder (not left to how
        # MuJoCo resolves an included file's assets) and a scene carries their bytes.
        robot = replace(robot, composition=Composition(arm=mjcf.resolve()))
    if robot.composition is not None:
        spec = robot_spec(robot.composition, robot.arm_joints, str(path))
        try:
            model = spec.compile()
        except ValueError as exc:
            raise SceneError(
                f"{path}: the composed robot does not compile: {' '.join(str(exc).split())}"
            ) from None
    else:
        try:
            model = mujoco.MjModel.from_xml_path(str(mjcf))
        except ValueError as exc:
            raise SceneError(
                f"{mjcf}: MuJoCo rejects the MJCF: {' '.join(str(exc).split())}"
            ) from None
    check_robot(robot, model, doc, mjcf.name, SceneError)
    _check_geom_group(robot, model, doc, mjcf.name)
    return robot


def _names_files(mjcf: Path) -> bool:
    """Whether the MJCF names mesh, texture, height-field or skin files."""
    try:
        spec = mujoco.MjSpec.from_file(str(mjcf))
    except ValueError as exc:
        raise SceneError(f"{mjcf}: MuJoCo rejects the MJCF: {' '.join(str(exc).split())}") from None
    return any(a.file for a in (*spec.meshes, *spec.textures, *spec.hfields, *spec.skins))


def robot_model_spec(robot: Robot) -> mujoco.MjSpec:
    """The robot alone as a spec: composed (:mod:`smccli.world.robot_compose`) or its MJCF
    as written."""
    if robot.composition is not None:
        return robot_spec(robot.composition, robot.arm_joints, str(robot.path))
    return mujoco.MjSpec.from_file(str(robot.mjcf_path))


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


def _composition(d: dict[str, Any], path: Path | None, arm_file: Path | None) -> Composition | None:
    """What the robot file asks smc to compose; None for an MJCF used as written (and for a
    robot rebuilt from a log, whose model is the log's)."""
    arm, g, poi = d.get("arm") or {}, d.get("gripper") or {}, d.get("poi")
    wanted = "urdf" in d or "mjcf" in g or "servo" in arm or "mount" in d or isinstance(poi, dict)
    if not wanted or path is None or arm_file is None:
        return None
    servo = arm.get("servo")
    n = len(arm.get("joints", ()))
    return Composition(
        arm=arm_file.resolve(),
        gripper=None
        if "mjcf" not in g
        else GripperFile(
            (path.parent / str(g["mjcf"])).resolve(),
            str(g["attach"]),
            frame_of(g.get("offset")),
            str(g.get("prefix", "gripper/")),
            tuple(
                (str(c["joint"]), str(c["to"]), float(c.get("ratio", 1.0)))
                for c in g.get("couple", ())
            ),
        ),
        servo=None
        if servo is None
        else Servo(
            tuple(
                float(k)
                for k in (servo["kp"] if isinstance(servo["kp"], list) else [servo["kp"]] * n)
            ),
            float(servo.get("dampratio", 1.0)),
            bool(servo.get("gravcomp", True)),
        ),
        poi=PoiPlacement(str(poi["at"]), frame_of(poi)) if isinstance(poi, dict) else None,
        mount=frame_of(d["mount"]) if "mount" in d else None,
    )


def _robot(doc: YamlDocument, text: str, path: Path | None, mjcf: Path | None) -> Robot:
    d: dict[str, Any] = doc.data
    arm, g, base = d.get("arm") or {}, d.get("gripper"), d.get("base")
    joints = tuple(str(j) for j in arm.get("joints", ()))
    actuators = tuple(str(a) for a in arm.get("actuators", ()))
    if "servo" in arm and not actuators:
        actuators = tuple(SERVO_PREFIX + j for j in joints)
    poi = d["poi"]
    return Robot(
        name=str(d["name"]),
        yaml_text=text,
        arm_joints=joints,
        arm_actuators=actuators,
        home=tuple(float(v) for v in arm.get("home", ())),
        poi=POI_SITE if isinstance(poi, dict) else str(poi),
        gripper=None
        if g is None
        else Gripper(
            joints=tuple(str(j) for j in g["joints"]),
            actuator=str(g["actuator"]),
            closed=float(g["opening"][0]),
            open=float(g["opening"][1]),
            commands=(float(g["commands"][0]), float(g["commands"][1]))
            if "commands" in g
            else None,
        ),
        base=Base(tuple(base["joints"]), tuple(base["actuators"])) if base else None,  # type: ignore[arg-type]
        geom_group=int(d["geom_group"]) if "geom_group" in d else None,
        composition=_composition(d, path, mjcf),
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
    the gripper points down, the first joint turns about the vertical (up or down) and the
    last rolls the gripper about its approach axis (either way): the POI's yaw is then
    ``±q_first ∓ q_last + a constant`` (:mod:`smccli.world.base_frame` reads the signs). A
    robot that breaks one reached its targets nowhere and said "out of reach"; here it gets
    the line that says what to fix."""
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
    if min(angle(first_axis, np.array([0.0, 0.0, s])) for s in (1.0, -1.0)) > ALONG:
        raise error_cls(
            f"{joints}: the first joint {first!r} turns about [{_vec3(first_axis)}], not the "
            "vertical: smc needs a base joint that turns the arm about z (a mount can turn "
            "an arm that stands on a wall upright)"
        )
    roll = angle(last_axis, approach)
    if min(roll, math.pi - roll) > ALONG:
        raise error_cls(
            f"{joints}: the last joint {last!r} does not roll the gripper about its approach "
            f"axis (its axis at home is {math.degrees(roll):.0f} deg from it): list the arm's "
            "joints base to flange, ending with the wrist roll"
        )


def _vec3(v: np.ndarray) -> str:
    return ", ".join(f"{float(x) + 0.0:.2f}" for x in v)


def _check_geom_group(robot: Robot, model: mujoco.MjModel, doc: YamlDocument, label: str) -> None:
    """Where the robot file gives ``geom_group`` (an override: lidar and self-filter then
    use that group alone), every geom of the robot's own MJCF is in it. Without it any
    groups are fine: the model says which geoms are the robot's."""
    if robot.geom_group is None:
        return
    for g in range(model.ngeom):
        if int(model.geom_group[g]) != robot.geom_group:
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"#{g}"
            raise SceneError(
                f"{doc.source}: {doc.where(('geom_group',))}: geom {name!r} of {label} is in "
                f"group {int(model.geom_group[g])}, not {robot.geom_group} (put every robot "
                "geom in one group)"
            )


def robot_geoms(robot: Robot, model: mujoco.MjModel) -> np.ndarray:
    """Ids of the robot's own geoms in a scene model: those of the bodies under the robot's
    root (the top body above its POI), restricted to ``geom_group`` where the robot file
    gives one; collision and visual geoms alike."""
    root = int(model.body_rootid[model.site_bodyid[model.site(robot.poi).id]])
    ids = [
        g
        for g in range(model.ngeom)
        if int(model.body_rootid[model.geom_bodyid[g]]) == root
        and (robot.geom_group is None or int(model.geom_group[g]) == robot.geom_group)
    ]
    return np.array(ids, dtype=int)


def robot_only_groups(robot: Robot, model: mujoco.MjModel) -> tuple[int, ...]:
    """The geom groups a sensor may skip to skip the robot: ``geom_group`` where the robot
    file gives it, else the groups the robot's geoms use and no other geom does (a group
    shared with the scene stays visible: its robot geoms are then seen)."""
    if robot.geom_group is not None:
        return (robot.geom_group,)
    mine = robot_geoms(robot, model)
    others = np.setdiff1d(np.arange(model.ngeom), mine)
    return tuple(
        int(g)
        for g in np.unique(model.geom_group[mine])
        if not np.any(model.geom_group[others] == g)
    )


def is_collision_geom(model: mujoco.MjModel, geom: int) -> bool:
    """A geom collides when its contype or conaffinity is non-zero; it is visual otherwise
    (what the model says, whatever group it sits in)."""
    return bool(model.geom_contype[geom] or model.geom_conaffinity[geom])


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
