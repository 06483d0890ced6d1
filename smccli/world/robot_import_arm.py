"""``smc robots import``: what the arm's file says (chain, flange, actuators or servos,
mount), and the composition the importer drafts with; see :mod:`smccli.world.robot_import`."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from smccli.errors import SceneError
from smccli.world.robot_compose import (
    Composition,
    Frame,
    GripperFile,
    Servo,
    robot_spec,
)
from smccli.world.robot_model import subtree_bodies

PREFIX = "gripper/"
FINGER_NAME = re.compile(r"grip|finger|jaw|claw", re.IGNORECASE)
"""A joint named like this is the gripper's, not the arm's."""
PINCH_SITE = re.compile(r"grip|pinch|tcp", re.IGNORECASE)
"""A site named like this is the gripper's own point between the pads."""
FLANGE_NAME = re.compile(r"hand|flange|attach|tool|(^|_)ee($|_)", re.IGNORECASE)
"""A joint-less body named like this, below the last arm joint, is the flange."""
ATTACH_SITE = re.compile(r"attach|flange", re.IGNORECASE)
"""A site of the flange body named like this is where the gripper attaches."""
SETTLE = 2.0
"""How long the gripper is driven to each end of its range [s]."""
KP_BIG, KP_WRIST = 3000.0, 800.0
"""docs/robots.md's gains for an arm of about 1 m and several kg [N m/rad]."""
BIG_MASS = 3.0
"""Moving mass from which those gains apply; lighter arms get them scaled down [kg]."""
HOME_PLACES = tuple(
    (ahead, up) for up in (0.3, 0.25, 0.2, 0.35, 0.15) for ahead in (0.4, 0.5, 0.35, 0.55, 0.3)
)
"""Home: the POI this share of the arm's reach in front of the first joint and above the
table (the first that the gripper reaches pointing down): the camera of the built-in
scenes looks at the objects from the far side of the table, over the arm's hand."""


@dataclass(frozen=True, slots=True)
class Guess:
    """One thing the importer guessed: what, its value, why."""

    what: str
    value: str
    why: str


@dataclass(frozen=True, slots=True)
class Draft:
    """A drafted robot file and the guesses behind it."""

    text: str
    guesses: tuple[Guess, ...]


def bad_file(path: Path, what: str) -> SceneError:
    return SceneError(f"{path}: {what}")


def _load_model(path: Path, where: Path) -> mujoco.MjModel:
    """A vendor's file compiled alone (its assets from its own folder)."""
    if not path.is_file():
        raise bad_file(path, "not a file")
    if path.suffix.lower() not in (".xml", ".urdf", ".mjcf"):
        raise bad_file(path, "not an MJCF (.xml) or URDF (.urdf) file")
    spec = robot_spec(Composition(arm=path.resolve()), (), str(where))
    try:
        return spec.compile()
    except ValueError as exc:
        raise bad_file(path, f"MuJoCo rejects it: {' '.join(str(exc).split())}") from None


def name_of(m: mujoco.MjModel, kind: mujoco.mjtObj, i: int) -> str:
    return mujoco.mj_id2name(m, kind, i) or ""


def _hinges_above(m: mujoco.MjModel, body: int) -> list[int]:
    """The arm-like hinge joints from the root to ``body``, root first."""
    out: list[int] = []
    b = body
    while b > 0:
        for j in range(m.body_jntadr[b], m.body_jntadr[b] + m.body_jntnum[b]):
            name = name_of(m, mujoco.mjtObj.mjOBJ_JOINT, j)
            if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and not FINGER_NAME.search(name):
                out.append(j)
        b = int(m.body_parentid[b])
    return out[::-1]


def arm_chain(m: mujoco.MjModel, path: Path) -> list[int]:
    """The joint ids of the longest hinge chain from the root (fingers left out)."""
    best = max((_hinges_above(m, b) for b in range(1, m.nbody)), key=len, default=[])
    if not best:
        raise bad_file(path, "no chain of hinge joints from its root body (not an arm)")
    return best


def flange(m: mujoco.MjModel, last_body: int) -> str:
    """Where a separate gripper attaches: the last arm body's joint-less descendant along
    single children (robosuite's ``right_hand``), else the last arm body; a site of that
    body named like attach or flange where it has one."""
    b = last_body
    while True:
        kids = [
            c
            for c in range(m.nbody)
            if m.body_parentid[c] == b and c != b and m.body_jntnum[c] == 0
        ]
        named = [c for c in kids if FLANGE_NAME.search(name_of(m, mujoco.mjtObj.mjOBJ_BODY, c))]
        pick = named or (kids if len(kids) == 1 else [])
        if not pick:
            break
        b = pick[0]
    sites = [  # a site made for it (Menagerie's attachment_site)
        name_of(m, mujoco.mjtObj.mjOBJ_SITE, s)
        for s in range(m.nsite)
        if m.site_bodyid[s] == b and ATTACH_SITE.search(name_of(m, mujoco.mjtObj.mjOBJ_SITE, s))
    ]
    return sites[0] if sites else name_of(m, mujoco.mjtObj.mjOBJ_BODY, b)


def actuators_on(m: mujoco.MjModel, joints: set[int]) -> list[int]:
    """Actuators whose transmission is one of ``joints`` or a tendon over them."""
    found = []
    for a in range(m.nu):
        trn, target = int(m.actuator_trntype[a]), int(m.actuator_trnid[a, 0])
        if trn == mujoco.mjtTrn.mjTRN_JOINT and target in joints:
            found.append(a)
        elif trn == mujoco.mjtTrn.mjTRN_TENDON:
            adr, num = m.tendon_adr[target], m.tendon_num[target]
            if any(int(m.wrap_objid[w]) in joints for w in range(adr, adr + num)):
                found.append(a)
    return found


def _is_motor(m: mujoco.MjModel, a: int) -> bool:
    return int(m.actuator_biastype[a]) == mujoco.mjtBias.mjBIAS_NONE


def servo_gains(m: mujoco.MjModel, chain: list[int]) -> tuple[tuple[float, ...], float]:
    """docs/robots.md's kp (3000 shoulder and elbow, 800 wrist: the first ceil(n/2) joints
    are the big ones), scaled by the moving mass over BIG_MASS where lighter; the mass [kg]."""
    moving = subtree_bodies(m, [int(m.jnt_bodyid[chain[0]])])
    mass = float(sum(m.body_mass[b] for b in moving))
    scale = min(1.0, mass / BIG_MASS)
    big = math.ceil(len(chain) / 2)
    kp = tuple(round((KP_BIG if i < big else KP_WRIST) * scale) for i in range(len(chain)))
    return kp, mass


def flow(v: object) -> str:
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(flow(x) for x in v) + "]"
    if isinstance(v, float):
        return f"{round(v, 6) + 0.0:g}"
    return str(v)


@dataclass(frozen=True, slots=True)
class ArmFound:
    """What the arm's file says."""

    path: Path
    model: mujoco.MjModel
    chain: list[int]
    names: list[str]
    actuators: list[str]
    servo: Servo | None
    flange: str
    mount: Frame | None


def read_arm(path: Path, where: Path, guesses: list[Guess]) -> ArmFound:
    """The arm's chain, actuators, flange and mount, each guess appended to ``guesses``."""
    m = _load_model(path, where)
    chain = arm_chain(m, path)
    names = [name_of(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in chain]
    last = int(m.jnt_bodyid[chain[-1]])
    fl = flange(m, last)
    guesses.append(
        Guess(
            "arm.joints",
            flow(names),
            f"the longest chain of hinge joints from the root ({len(chain)}), to body "
            f"{name_of(m, mujoco.mjtObj.mjOBJ_BODY, last)!r}; flange {fl!r}",
        )
    )
    acts: list[str] = []
    motors = 0
    for j in chain:
        on = actuators_on(m, {j})
        if on:
            acts.append(name_of(m, mujoco.mjtObj.mjOBJ_ACTUATOR, on[0]))
            motors += _is_motor(m, on[0])
    servo = None
    if len(acts) < len(chain) or motors:
        kp, mass = servo_gains(m, chain)
        servo = Servo(kp)
        why = (
            "its actuators on these joints are torque motors (no position bias)"
            if motors
            else f"only {len(acts)} of the {len(chain)} joints have an actuator"
        )
        guesses.append(
            Guess(
                "arm.servo.kp",
                flow(kp),
                f"{why}: docs/robots.md's 3000 (shoulder, elbow) and 800 (wrist) for a "
                f"moving mass of {mass:.1f} kg (scaled below {BIG_MASS:g} kg)",
            )
        )
        acts = []
    else:
        guesses.append(
            Guess("arm.actuators", flow(acts), "the position actuator on each chain joint")
        )
    mount = _mount(m, chain, guesses)
    return ArmFound(path, m, chain, names, acts, servo, fl, mount)


def _mount(m: mujoco.MjModel, chain: list[int], guesses: list[Guess]) -> Frame | None:
    """A mount putting the first joint's axis at the origin, the arm reaching along +x at
    zero (where its file puts it elsewhere)."""
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    anchor = d.xanchor[chain[0]].copy()
    tip = d.xpos[int(m.jnt_bodyid[chain[-1]])] - anchor
    # The arm reaches in the plane the second joint swings: across its axis, towards the tip.
    across = np.cross(d.xaxis[chain[1]], [0.0, 0.0, 1.0]) if len(chain) > 1 else tip
    if np.hypot(across[0], across[1]) < 0.5:
        across = tip
    if across @ tip < 0:
        across = -across
    heading = math.atan2(across[1], across[0]) if np.hypot(across[0], across[1]) > 0.01 else 0.0
    quarter = round(heading / (math.pi / 2)) * math.pi / 2
    if abs(heading - quarter) < math.radians(2):
        heading = quarter
    if abs(heading) < math.radians(5):
        heading = 0.0
    if abs(heading) < 1e-9 and np.hypot(anchor[0], anchor[1]) < 1e-3:
        return None
    c, s = math.cos(-heading), math.sin(-heading)
    pos = (-(c * anchor[0] - s * anchor[1]), -(s * anchor[0] + c * anchor[1]), 0.0)
    quat = (math.cos(-heading / 2), 0.0, 0.0, math.sin(-heading / 2))
    guesses.append(
        Guess(
            "mount",
            f"pos {flow(pos)}, yaw {math.degrees(-heading):.0f} deg",
            f"the first joint's axis is at ({anchor[0]:.3f}, {anchor[1]:.3f}) and the arm "
            f"reaches {math.degrees(heading):.0f} deg from +x at zero; the controller wants "
            "the axis at the origin reaching along +x",
        )
    )
    return Frame(tuple(round(p, 6) for p in pos), quat)  # type: ignore[arg-type]


def compose(arm: ArmFound, gripper: Path | None, where: Path, **extra: object) -> mujoco.MjSpec:
    g = None
    if gripper is not None:
        g = GripperFile(
            gripper.resolve(),
            arm.flange,
            Frame(),
            PREFIX,
            extra.get("couple", ()),  # type: ignore[arg-type]
        )
    return robot_spec(
        Composition(
            arm=arm.path.resolve(),
            gripper=g,
            servo=arm.servo,
            poi=extra.get("poi"),  # type: ignore[arg-type]
            mount=arm.mount,
        ),
        tuple(arm.names),
        str(where),
    )
