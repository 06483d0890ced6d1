"""A robot composed from its makers' files, unedited: the arm's MJCF or URDF, a gripper's MJCF
attached to it, and what smc adds to the composed spec (never to the files): position servos
on an arm driven by torque motors, a POI site, the mount in the world and the contact options
a grasp needs.

Each file is loaded alone with ``mujoco.MjSpec.from_file`` (a URDF's ``package://`` paths
resolved first, :func:`package_roots`), so its meshes and textures resolve from its own
folder; their paths are then made absolute, and :func:`robot_xml` writes one self-contained
MJCF that compiles from any folder. The gripper is attached with a name prefix
(``gripper/`` by default), so its names cannot clash with the arm's.
"""

from __future__ import annotations

import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

import mujoco
import numpy as np

from smccli.errors import SceneError

PACKAGE_PATH_VARS = ("SMC_PACKAGE_PATH", "ROS_PACKAGE_PATH")
"""Environment variables listing folders (``:``-separated) that hold a URDF's packages."""
POI_SITE = "smc/poi"
"""The site smc adds when the robot file places the POI on a body (``poi: {body: ...}``)."""
SERVO_PREFIX = "smc/servo/"
"""Name prefix of the position servos smc adds on an arm's joints (``arm.servo``)."""


@dataclass(frozen=True, slots=True)
class Frame:
    """A placement relative to a parent frame: position [m] and unit quaternion (w, x, y, z)."""

    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True)
class GripperFile:
    """A gripper shipped as its own MJCF, attached to a site or body of the arm."""

    mjcf: Path
    attach: str
    """The arm's site or body it is attached to (its root body's frame goes there)."""
    offset: Frame
    prefix: str = "gripper/"
    couple: tuple[tuple[str, str, float], ...] = ()
    """``(joint, to, ratio)``: ``joint`` follows ``to`` (``q_joint = ratio * q_to``, a joint
    equality) and the vendor's actuators on ``joint`` are left out, so that one actuator
    drives the gripper (robosuite's grippers drive each finger by its own)."""


@dataclass(frozen=True, slots=True)
class Servo:
    """Position servos smc puts on the arm joints (the vendor's actuators are torque motors)."""

    kp: tuple[float, ...]
    """Stiffness per arm joint [N m/rad or N/m]."""
    dampratio: float = 1.0
    gravcomp: bool = True
    """Compensate gravity on the arm's moving bodies (and the gripper's)."""


@dataclass(frozen=True, slots=True)
class PoiPlacement:
    """The POI as a site smc adds to a body (or site) of the composed robot."""

    at: str
    frame: Frame


@dataclass(frozen=True, slots=True)
class Composition:
    """What a robot file asks smc to compose (all paths absolute)."""

    arm: Path
    """The arm's MJCF or URDF (``.urdf``)."""
    gripper: GripperFile | None = None
    servo: Servo | None = None
    poi: PoiPlacement | None = None
    mount: Frame | None = None
    """Where the robot's root bodies go in the world; None: where its file puts them."""


def frame_of(raw: dict | None) -> Frame:
    """A :class:`Frame` from a robot file's ``{pos, quat}`` or ``{pos, euler}`` (xyz, [rad])."""
    raw = raw or {}
    pos = tuple(float(v) for v in raw.get("pos", (0.0, 0.0, 0.0)))
    if "euler" in raw:
        quat = np.zeros(4)
        mujoco.mju_euler2Quat(quat, np.array(raw["euler"], dtype=float), "xyz")
    else:
        quat = np.array(raw.get("quat", (1.0, 0.0, 0.0, 0.0)), dtype=float)
        quat /= np.linalg.norm(quat)
    return Frame(pos, tuple(float(v) for v in quat))  # type: ignore[arg-type]


def package_roots(robot_dir: Path, urdf: Path) -> list[Path]:
    """Where a URDF's ``package://NAME/...`` is looked for, in order: the robot file's
    folder, the URDF's folder and its ancestors, then the folders of ``SMC_PACKAGE_PATH``
    and ``ROS_PACKAGE_PATH``. ``NAME`` is ``root/NAME`` or a root called ``NAME``."""
    roots = [robot_dir, urdf.parent, *urdf.parent.parents]
    for var in PACKAGE_PATH_VARS:
        roots += [Path(p) for p in os.environ.get(var, "").split(os.pathsep) if p]
    return roots


def _urdf_text(urdf: Path, robot_dir: Path) -> str:
    """The URDF's text with ``package://`` paths made absolute, and MuJoCo's URDF options
    (keep every link a body, skip visual meshes MuJoCo cannot read, keep full paths) unless
    the file gives its own ``<mujoco>`` element."""
    text = urdf.read_text()
    roots = package_roots(robot_dir, urdf)

    def resolve(m: re.Match[str]) -> str:
        name = m.group(1)
        for root in roots:
            for folder in (root / name, root):
                if folder.name == name and folder.is_dir():
                    return f"{folder.resolve()}/"
        raise SceneError(
            f"{urdf}: package://{name} not found (looked in {', '.join(map(str, roots))}; "
            f"add its parent folder to {PACKAGE_PATH_VARS[0]})"
        )

    text = re.sub(r"package://([^/\"']+)/", resolve, text)
    if "<mujoco>" not in text:
        options = (
            '<mujoco><compiler fusestatic="false" discardvisual="true" strippath="false"/></mujoco>'
        )
        text = re.sub(r"(<robot\b[^>]*>)", r"\1" + options, text, count=1)
    return text


_UNKNOWN_ATTRIBUTE = re.compile(r"unrecognized attribute: '([^']+)'\s+Element '([^']+)'")
"""MuJoCo's parse error for an attribute its schema does not have on an element."""
_MAX_DROPPED = 16


def _mjcf_spec(path: Path) -> mujoco.MjSpec:
    """An MJCF file as a spec. An attribute MuJoCo's schema does not know on an element
    (robosuite 1.5.2's xArm gripper puts ``group`` on a ``<default>``: older MuJoCo let it
    pass) is dropped from every such element, with a warning naming the file, rather than
    the vendor's file refused: it never meant anything to MuJoCo."""
    try:
        return mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:
        first = exc
    root = ElementTree.parse(path).getroot()
    dropped: list[str] = []
    while len(dropped) < _MAX_DROPPED:
        m = _UNKNOWN_ATTRIBUTE.search(str(first))
        if m is None:
            raise first
        attr, tag = m.groups()
        hits = [e for e in root.iter(tag) if attr in e.attrib]
        if not hits:
            raise first
        for e in hits:
            del e.attrib[attr]
        dropped.append(f"{attr!r} on <{tag}>")
        try:
            spec = mujoco.MjSpec.from_string(ElementTree.tostring(root, encoding="unicode"))
        except ValueError as exc:
            first = exc
            continue
        spec.modelfiledir = str(path.parent)
        warnings.warn(
            f"{path}: MuJoCo {mujoco.__version__} does not know {', '.join(dropped)}: "
            "left out (the file is not changed)",
            stacklevel=2,
        )
        return spec
    raise first


def _load(path: Path, robot_dir: Path) -> mujoco.MjSpec:
    """One file as a spec whose asset files are absolute paths (from its own folder)."""
    try:
        if path.suffix.lower() == ".urdf":
            spec = mujoco.MjSpec.from_string(_urdf_text(path, robot_dir))
            spec.modelfiledir = str(path.parent)
        else:
            spec = _mjcf_spec(path)
    except ValueError as exc:
        raise SceneError(f"{path}: MuJoCo rejects the file: {' '.join(str(exc).split())}") from None
    folder = Path(spec.modelfiledir or path.parent)
    for assets, subdir in (
        (spec.meshes, spec.meshdir),
        (spec.textures, spec.texturedir),
        (spec.hfields, spec.meshdir),
        (spec.skins, spec.meshdir),
    ):
        for asset in assets:
            if asset.file:
                asset.file = os.path.normpath(folder / subdir / asset.file)
    spec.meshdir = ""
    spec.texturedir = ""
    return spec


def _frame_at(spec: mujoco.MjSpec, name: str, where: str) -> mujoco.MjsFrame:
    """A new frame at the arm's site or body ``name``."""
    site = spec.site(name)
    if site is not None:
        body = site.parent
        return body.add_frame(pos=site.pos, quat=site.quat)
    body = spec.body(name)
    if body is None:
        raise SceneError(f"{where}: the arm has no site or body {name!r}")
    return body.add_frame()


def robot_spec(comp: Composition, arm_joints: tuple[str, ...], where: str) -> mujoco.MjSpec:
    """The composed robot: arm, gripper attached, servos on ``arm_joints`` (if asked), POI
    site, mount and grasp options. ``where``: the robot file, for errors (SceneError naming
    the file and the key)."""
    robot_dir = Path(where).parent
    spec = _load(comp.arm, robot_dir)
    if comp.gripper is not None:
        g = comp.gripper
        gspec = _load(g.mjcf, robot_dir)
        frame = _frame_at(spec, g.attach, f"{where}: gripper.attach")
        inner = frame.add_frame(pos=g.offset.pos, quat=g.offset.quat)
        _same_options(gspec, spec)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for body in _roots(gspec):
                inner.attach_body(body, g.prefix, "")
        _couple(spec, g.couple, f"{where}: gripper.couple")
    if comp.poi is not None:
        p = comp.poi
        site = spec.site(p.at)
        parent = site.parent if site is not None else spec.body(p.at)
        if parent is None:
            raise SceneError(f"{where}: poi.at: the robot has no body or site {p.at!r}")
        frame = parent.add_frame(pos=site.pos, quat=site.quat) if site is not None else parent
        frame.add_site(name=POI_SITE, pos=p.frame.pos, quat=p.frame.quat, size=[0.004] * 3)
    if comp.servo is not None:
        missing = [j for j in arm_joints if spec.joint(j) is None]
        if missing:
            raise SceneError(f"{where}: arm.joints: no joint {missing[0]!r} in {comp.arm}")
        add_servos(spec, arm_joints, comp.servo)
    if comp.mount is not None:
        mount = spec.worldbody.add_frame(pos=comp.mount.pos, quat=comp.mount.quat)
        for body in _roots(spec):
            body.set_frame(mount)
    grasp_options(spec)
    return spec


def _couple(spec: mujoco.MjSpec, couple: tuple[tuple[str, str, float], ...], where: str) -> None:
    """Each ``joint`` follows ``to`` by a joint equality; actuators on ``joint`` go."""
    for joint, to, ratio in couple:
        for name in (joint, to):
            if spec.joint(name) is None:
                raise SceneError(f"{where}: the composed robot has no joint {name!r}")
        spec.add_equality(
            type=mujoco.mjtEq.mjEQ_JOINT,
            objtype=mujoco.mjtObj.mjOBJ_JOINT,
            name1=joint,
            name2=to,
            data=[0.0, ratio] + [0.0] * 10,
        )
        for act in list(spec.actuators):
            if act.trntype == mujoco.mjtTrn.mjTRN_JOINT and act.target == joint:
                spec.delete(act)


def _same_options(child: mujoco.MjSpec, parent: mujoco.MjSpec) -> None:
    """The parent's physics options in the child: a gripper file's own ``<option>`` (robosuite's
    bd_gripper turns gravity off) applies to nothing once attached, and MuJoCo would warn
    on stderr that it keeps the parent's."""
    for name in dir(parent.option):
        if not name.startswith("_"):
            try:
                setattr(child.option, name, getattr(parent.option, name))
            except (AttributeError, TypeError):
                pass


def _roots(spec: mujoco.MjSpec) -> list[mujoco.MjsBody]:
    return list(spec.worldbody.bodies)


def add_servos(spec: mujoco.MjSpec, joints: tuple[str, ...], servo: Servo) -> tuple[str, ...]:
    """Position servos on ``joints`` (ctrlrange the joint's range, force capped where a
    vendor motor drives the joint at its ctrlrange); gravity compensation on the bodies the
    joints move. Returns the servos' names, in the joints' order."""
    motors = {a.target: a for a in spec.actuators if a.trntype == mujoco.mjtTrn.mjTRN_JOINT}
    names = []
    for joint, kp in zip(joints, servo.kp, strict=True):
        j = spec.joint(joint)
        act = spec.add_actuator(name=SERVO_PREFIX + joint, target=joint)
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.set_to_position(kp=kp, dampratio=servo.dampratio)
        if j is not None and j.range[0] < j.range[1]:
            act.ctrlrange = j.range
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        motor = motors.get(joint)
        if motor is not None and motor.ctrlrange[0] < motor.ctrlrange[1]:
            act.forcerange = np.asarray(motor.ctrlrange) * float(motor.gear[0])
            act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        names.append(act.name)
    if servo.gravcomp:
        first = spec.joint(joints[0])
        top = first.parent if first is not None else None
        for body in [top, *top.find_all(mujoco.mjtObj.mjOBJ_BODY)] if top is not None else ():
            body.gravcomp = 1.0
    return tuple(names)


def grasp_options(spec: mujoco.MjSpec) -> None:
    """Elliptic friction cones and ``impratio`` 10 (with MuJoCo's defaults objects slip out
    of a grip during fast moves) and the implicit-fast integrator, where the spec leaves
    MuJoCo's defaults; a scene's ``<option>`` (included after the robot) may refine them."""
    opt = spec.option
    if opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL:
        opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    if opt.impratio == 1.0:
        opt.impratio = 10.0
    if opt.integrator == mujoco.mjtIntegrator.mjINT_EULER:
        opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST


def asset_files(spec: mujoco.MjSpec) -> dict[str, bytes]:
    """The bytes of every file the spec's assets name (absolute paths, :func:`_load`): what
    a log stores so the composed model compiles where the vendor's folder is not."""
    out = {}
    for assets in (spec.meshes, spec.textures, spec.hfields, spec.skins):
        for asset in assets:
            if asset.file and asset.file not in out:
                out[asset.file] = Path(asset.file).read_bytes()
    return out


def names_by_kind(spec: mujoco.MjSpec) -> dict[str, set[str]]:
    """The named elements of a spec, by MJCF kind (for clash messages)."""
    kinds = {
        "body": spec.bodies,
        "geom": spec.geoms,
        "site": spec.sites,
        "joint": spec.joints,
        "camera": spec.cameras,
        "light": spec.lights,
        "actuator": spec.actuators,
        "sensor": spec.sensors,
        "tendon": spec.tendons,
        "material": spec.materials,
        "mesh": spec.meshes,
        "texture": spec.textures,
    }
    return {k: {e.name for e in v if e.name and e.name != "world"} for k, v in kinds.items()}
