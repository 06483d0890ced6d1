"""What ``smc robots`` checks in simulation that a robot file otherwise takes on trust.

:func:`check_robot` (:mod:`smccli.world.robot`) checks the file against its MJCF: names,
counts, limits, axes. :func:`simulation_checks` then runs the robot in a scene (the
scene given, else a table holding the robot alone) and measures:

- ``gripper``: driven with the file's closed and open commands until it settles, every
  finger joint travels at least half the way the file says, and the pads end nearer each
  other closed than open (a tendon gripper commanded outside its actuator's units does not
  move; swapped commands open it when told to close);
- ``home_contacts``: at home with the gripper open, no geom the arm moves touches anything;
- ``home_view``: at home, the arm's bounding spheres (:func:`~smccli.world.robot_view.
  link_spheres`) projected through the scene's camera cover at most VIEW_SHARE of the
  image where each object's range lies (the first decision perceives the table with the
  arm at home);
- ``reach``: the POI reaches each object's range on a grid, pointing down at the object's
  yaw (or the half turn the gripper's symmetry allows), by the controller's IK;
- ``poi``: at the open posture the POI lies between the two pads along its y axis (the
  finger travel), at least a quarter of the gap from each (a one-jaw gripper's POI may lie
  nearer its fixed jaw, POI_HOLD), and within the pads' extent along the other two axes;
  with two fingers, closed, they meet near it. A pad is the part of a finger's contact
  geom within PAD_WINDOW of the POI along its z (a mesh's by its vertices, a primitive's
  by its box).

Each finding is data: the check, its status, what was measured and one line saying what
to fix. A mobile base has its arm carried to the objects: reach and view are skipped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import mujoco
import numpy as np

from smccli.errors import SceneError
from smccli.world.controller import CartesianController, reach_problem
from smccli.world.robot import Robot, arm_reach, robot_model_spec
from smccli.world.robot_model import subtree_bodies
from smccli.world.robot_view import PinholeView, geom_box, link_spheres, range_corners
from smccli.world.specs import ObjectSpec, Scene

Status = Literal["pass", "fail", "skip"]

SETTLE_MAX = 3.0
"""Longest the gripper is simulated after a command [s]."""
SETTLE_SPEED = 1e-3
"""The fingers have settled when every finger joint moves slower than this [m/s or rad/s]."""
TRAVEL_SHARE = 0.5
"""Each finger joint must travel at least this share of the file's closed-to-open travel."""
PAD_CLOSING = 0.002
"""Closing must bring the pads at least this much nearer each other [m]."""
CONTACT_DEPTH = 5e-4
"""A contact at home counts from this penetration [m] (touching surfaces give ~0)."""
POI_SHARE = 0.25
"""At the open posture the POI keeps this share of the gap from each pad."""
PAD_WINDOW = 0.02
"""A pad is the part of a finger's contact geom within this of the POI along its z [m]:
the importer's gripping stretch (``PAD_DEPTH``, 4 cm) centred on it."""
POI_HOLD = 0.01
"""A one-jaw gripper's POI may lie this near the fixed jaw, less than POI_SHARE of a wide
gap [m]: an object 2 cm across held against it has its centre there."""
POI_TOLERANCE = 0.005
"""How far outside the pads' extent (approach and width) the POI may lie [m]."""
VIEW_SHARE = 0.01
"""The arm may cover this share of an object's image region at home: its bounding spheres
exceed the links (a box's sphere holds its corners), measured 0.15 % on docs/robots.md's
arm (3 of 2,041 pixels; 0 rendered)."""
REACH_GRID = 3
"""Samples per randomised dimension (x, y, yaw) of an object's range."""
REACH_BUDGET = 240
"""At most this many places are sampled over all objects (IK solves, before the half turn)."""
PLACE_ABOVE = 0.05
"""A container's or a scale's place: the POI this far above its top [m] (a release)."""
MIN_Z = 0.01
"""Lowest POI height :func:`~smccli.world.controller.reach_problem` accepts [m]."""


@dataclass(frozen=True, slots=True)
class Finding:
    """One simulation check's outcome."""

    check: str
    """``gripper``, ``home_contacts``, ``home_view``, ``reach`` or ``poi``."""
    status: Status
    measured: str
    """What was measured, in a few words with units."""
    fix: str = ""
    """One line saying what to change (empty when it passed)."""


@dataclass(frozen=True, slots=True)
class Postures:
    """The gripper's settled postures: the whole ``qpos`` after the closed and the open
    command, and each finger joint's value there."""

    closed: np.ndarray
    open: np.ndarray
    finger_closed: np.ndarray
    finger_open: np.ndarray
    hand_open: tuple[tuple[str, float], ...]
    """Each hinge or slide joint past the wrist roll (fingers, coupled ones and linkages)
    and its value after the open command: what another model of the robot takes by name."""


@dataclass
class _Bench:
    """The robot in its model: ids the checks share."""

    robot: Robot
    model: mujoco.MjModel
    scene: Scene | None

    def __post_init__(self) -> None:
        m, r = self.model, self.robot
        self.data = mujoco.MjData(m)
        self.site = m.site(r.poi).id
        self.arm_q = np.array([m.jnt_qposadr[m.joint(n).id] for n in r.arm_joints], dtype=int)
        self.arm_act = np.array([m.actuator(n).id for n in r.arm_actuators], dtype=int)
        first = int(m.jnt_bodyid[m.joint(r.arm_joints[0]).id]) if r.arm_joints else 0
        self.moving = subtree_bodies(m, [first]) if first else set()
        """Bodies the arm's joints move (its fixed base excluded)."""
        g = r.gripper
        self.finger_j = [m.joint(n).id for n in g.joints] if g else []
        self.finger_q = np.array([m.jnt_qposadr[j] for j in self.finger_j], dtype=int)
        self.finger_v = np.array([m.jnt_dofadr[j] for j in self.finger_j], dtype=int)
        self.fingers = subtree_bodies(m, [int(m.jnt_bodyid[j]) for j in self.finger_j])
        """Bodies the finger joints move."""

    def home_state(self) -> None:
        """``data`` at the model's reference state with the arm at home (kinematics)."""
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[self.arm_q] = self.robot.home
        d.ctrl[self.arm_act] = self.robot.home
        mujoco.mj_forward(m, d)


def _geom_name(model: mujoco.MjModel, g: int) -> str:
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)
    body = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, int(model.geom_bodyid[g]))
    return repr(name) if name else f"a geom of body {body!r}"


def robot_alone(robot: Robot, *, table: bool = True) -> mujoco.MjModel:
    """The robot alone, on a table (a plane at the table top, z = 0, where the built-in
    scenes put it) or without; no objects, no camera."""
    if robot.mjcf_path is None:
        raise SceneError(f"robot {robot.name}: no MJCF file to check")
    try:
        spec = robot_model_spec(robot)  # a vendor's files composed, or the MJCF as written
        if table:
            spec.worldbody.add_geom(
                name="smc_check_table", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[2.0, 2.0, 0.1]
            )
        return spec.compile()
    except ValueError as exc:
        raise SceneError(f"{robot.mjcf_path}: {' '.join(str(exc).split())}") from None


def simulation_checks(robot: Robot, scene: Scene | None = None) -> list[Finding]:
    """The simulation checks of ``robot`` (the robot of ``scene`` when one is given, in it;
    else on a table alone), in the order of the module docstring."""
    robot = scene.robot if scene is not None else robot
    if not robot.arm_joints:
        skip = "a base without an arm"
        checks = ("gripper", "home_contacts", "home_view", "reach", "poi")
        return [Finding(c, "skip", skip) for c in checks]
    # The gripper on the robot alone, with nothing to touch but itself: a home posture in
    # the table is home_contacts' finding, not the gripper's.
    hand = _Bench(robot, robot_alone(robot, table=False), None)
    bench = _Bench(robot, scene.model() if scene else robot_alone(robot), scene)
    gripper, postures = check_gripper(hand)
    return [
        gripper,
        check_home_contacts(bench, postures),
        check_home_view(bench, postures),
        check_reach(bench),
        check_poi(hand, postures, gripper.status == "pass"),
    ]


# --- the gripper ------------------------------------------------------------------------


def _settle(bench: _Bench, command: float) -> None:
    """Drive the gripper actuator at ``command`` until the fingers stop (or SETTLE_MAX)."""
    m, d = bench.model, bench.data
    assert bench.robot.gripper is not None
    d.ctrl[m.actuator(bench.robot.gripper.actuator).id] = command
    still = 0
    for _ in range(int(SETTLE_MAX / m.opt.timestep)):
        mujoco.mj_step(m, d)
        if np.abs(d.qvel[bench.finger_v]).max() < SETTLE_SPEED and d.time > 0.1:
            still += 1
            if still * m.opt.timestep >= 0.05:
                break
        else:
            still = 0


_HINGE_SLIDE = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


def settle_gripper(bench: _Bench) -> Postures | None:
    """The robot at home, its gripper driven closed then open (from open), settled each
    time; None without a gripper."""
    g = bench.robot.gripper
    if g is None:
        return None
    bench.home_state()
    lo, hi = bench.model.jnt_range[bench.finger_j].T
    bench.data.qpos[bench.finger_q] = np.clip(g.open, lo, hi)
    mujoco.mj_forward(bench.model, bench.data)
    _settle(bench, g.target(0.0))
    closed = bench.data.qpos.copy()
    _settle(bench, g.target(1.0))
    opened = bench.data.qpos.copy()
    m = bench.model
    wrist = subtree_bodies(m, [int(m.jnt_bodyid[m.joint(bench.robot.arm_joints[-1]).id])])
    hand = tuple(  # every joint past the wrist: a coupled finger, a linkage's
        (m.joint(j).name, float(opened[m.jnt_qposadr[j]]))
        for j in range(m.njnt)
        if int(m.jnt_bodyid[j]) in wrist
        and m.joint(j).name not in bench.robot.arm_joints
        and int(m.jnt_type[j]) in _HINGE_SLIDE
    )
    return Postures(closed, opened, closed[bench.finger_q], opened[bench.finger_q], hand)


def check_gripper(bench: _Bench) -> tuple[Finding, Postures | None]:
    """``gripper``: each finger joint's travel from the closed to the open command against
    the robot file's, and the pads' gap along the POI's y after each."""
    postures = settle_gripper(bench)
    g = bench.robot.gripper
    if postures is None or g is None:
        return Finding("gripper", "skip", "no gripper"), None
    m = bench.model
    lo, hi = m.jnt_range[bench.finger_j].T
    limited = m.jnt_limited[bench.finger_j].astype(bool)
    span = np.where(limited, hi - lo, np.inf)
    for name, a, b, s in zip(g.joints, lo, hi, span, strict=True):
        if not (a - s <= min(g.closed, g.open) and max(g.closed, g.open) <= b + s):
            measured = f"finger joint {name} moves in [{a:g}, {b:g}]"
            fix = (
                f"gripper.opening [{g.closed:g}, {g.open:g}] gives each finger joint's "
                f"position when closed and open, in its range [{a:g}, {b:g}] (the actuator's "
                "own units go in gripper.commands)"
            )
            return Finding("gripper", "fail", measured, fix), postures
    # The file's travel: closed may lie past the limit (the squeeze is then the force cap).
    expected = np.where(
        limited, np.clip(g.open, lo, hi) - np.clip(g.closed, lo, hi), g.open - g.closed
    )
    travel = postures.finger_open - postures.finger_closed
    moved = ", ".join(
        f"{n} {_joint_amount(m, j, t)} of {_joint_amount(m, j, e)}"
        for n, j, t, e in zip(g.joints, bench.finger_j, travel, expected, strict=True)
    )
    measured = f"from the closed to the open command: {moved}"
    if any(t * np.sign(e) < TRAVEL_SHARE * abs(e) for t, e in zip(travel, expected, strict=True)):
        return Finding("gripper", "fail", measured, _travel_fix(bench)), postures
    gaps = [_pad_gap(bench, q) for q in (postures.closed, postures.open)]
    if all(np.isfinite(gaps)):
        measured += f"; pads {gaps[0] * 1000:.0f} mm apart closed, {gaps[1] * 1000:.0f} mm open"
        if gaps[1] - gaps[0] < PAD_CLOSING:
            key = "opening" if (g.target(0.0), g.target(1.0)) == (g.closed, g.open) else "commands"
            fix = f"the closed and open commands are swapped: swap gripper.{key} (closed first)"
            return Finding("gripper", "fail", measured, fix), postures
    return Finding("gripper", "pass", measured), postures


def _joint_amount(m: mujoco.MjModel, j: int, value: float) -> str:
    """A finger joint's displacement with its unit: mm for a slide, deg for a hinge."""
    if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE:
        return f"{value * 1000:.1f} mm"
    return f"{math.degrees(value):.1f} deg"


def _travel_fix(bench: _Bench) -> str:
    """What to change when the fingers do not follow the commands."""
    m, g = bench.model, bench.robot.gripper
    assert g is not None
    act = m.actuator(g.actuator).id
    closed, opened = g.target(0.0), g.target(1.0)
    lo, hi = m.actuator_ctrlrange[act]
    name = repr(g.actuator)
    through = "a tendon" if m.actuator_trntype[act] == mujoco.mjtTrn.mjTRN_TENDON else "a joint"
    if m.actuator_ctrllimited[act] and abs(opened - closed) < 0.1 * (hi - lo):
        return (
            f"actuator {name} (on {through}) takes commands in [{lo:g}, {hi:g}]; the closed "
            f"and open commands {closed:g} and {opened:g} move it by "
            f"{abs(opened - closed) / (hi - lo):.1%} of that: give them in its units "
            "(gripper.commands)"
        )
    return (
        f"actuator {name} (on {through}) does not take the fingers from {closed:g} to "
        f"{opened:g}: check its gain, its force range and the fingers' limits"
    )


def _pads(bench: _Bench, q: np.ndarray) -> list[list[int]]:
    """The contact geoms of each side of the gripper at posture ``q``: one side per
    finger joint; a one-jaw gripper's second side is the fixed jaw, the hand's contact
    geoms. Each side's list is ordered nearest the POI first (its pad within PAD_WINDOW
    along the POI's z, else its whole extent)."""
    m, d = bench.model, bench.data
    d.qpos[:] = q
    mujoco.mj_kinematics(m, d)
    collides = (m.geom_contype != 0) | (m.geom_conaffinity != 0)
    sides = []
    for j in bench.finger_j:
        bodies = subtree_bodies(m, [int(m.jnt_bodyid[j])])
        sides.append([g for g in range(m.ngeom) if int(m.geom_bodyid[g]) in bodies and collides[g]])
    if len(sides) == 1:
        last = int(m.jnt_bodyid[m.joint(bench.robot.arm_joints[-1]).id])
        hand = subtree_bodies(m, [last]) - bench.fingers
        sides.append([g for g in range(m.ngeom) if int(m.geom_bodyid[g]) in hand and collides[g]])
    if not all(sides):
        return []

    def from_poi(g: int) -> tuple[float, float]:  # nearest point of its pad, of its extent
        pad, whole = _box(bench, g), _box(bench, g, window=False)
        assert whole is not None
        near = np.inf if pad is None else float(np.linalg.norm(np.clip(0.0, *pad)))
        return near, float(np.linalg.norm(np.clip(0.0, *whole)))

    return [sorted(side, key=from_poi) for side in sides]


def _box(bench: _Bench, g: int, *, window: bool = True) -> np.ndarray | None:
    """Geom ``g``'s box in the POI site's frame (:func:`~smccli.world.robot_view.
    geom_box`), with ``window`` only its part within PAD_WINDOW of the POI along its z: a
    mesh jaw's box is that of its fingertip, not of the whole part it is moulded with."""
    d, site = bench.data, bench.site
    frame = (d.site_xpos[site], d.site_xmat[site].reshape(3, 3))
    return geom_box(bench.model, d, g, frame, PAD_WINDOW if window else None)


def _pad_boxes(bench: _Bench, sides: list[list[int]]) -> tuple[np.ndarray, np.ndarray, bool]:
    """The two sides' nearest pads' boxes (:func:`_box`), each within PAD_WINDOW of the
    POI where both have a part there (then True), else their whole extents (False)."""
    pads = [_box(bench, s[0]) for s in sides]
    near = all(p is not None for p in pads)
    if not near:
        pads = [_box(bench, s[0], window=False) for s in sides]
    a, b = pads
    assert a is not None and b is not None
    return a, b, near


def _pad_gap(bench: _Bench, q: np.ndarray) -> float:
    """Gap between the two sides' pads along the POI's y axis at posture ``q`` [m]
    (negative: they overlap)."""
    sides = _pads(bench, q)
    if len(sides) != 2:
        return float("nan")
    a, b, near = _pad_boxes(bench, sides)
    if not near:  # a jaw swung away from the POI: no gap across it
        return float("nan")
    if a[:, 1].mean() > b[:, 1].mean():
        a, b = b, a
    return float(b[0, 1] - a[1, 1])


# --- home -------------------------------------------------------------------------------


def _home_open(bench: _Bench, postures: Postures | None) -> None:
    """``data`` at home with the gripper as it settled open (kinematics, contacts)."""
    bench.home_state()
    if postures is not None:  # the hand's joints (linkages too) as the open command left them
        for name, q in postures.hand_open:
            bench.data.qpos[bench.model.jnt_qposadr[bench.model.joint(name).id]] = q
    mujoco.mj_forward(bench.model, bench.data)


def check_home_contacts(bench: _Bench, postures: Postures | None) -> Finding:
    """``home_contacts``: at home, gripper open, no geom the arm moves penetrates another
    geom (the table, an object at its nominal pose, another link) by CONTACT_DEPTH."""
    _home_open(bench, postures)
    m, d = bench.model, bench.data
    worst: tuple[float, int, int] | None = None
    for c in d.contact[: d.ncon]:
        g1, g2 = int(c.geom[0]), int(c.geom[1])
        ours = {int(m.geom_bodyid[g1]), int(m.geom_bodyid[g2])} & bench.moving
        if ours and c.dist < -CONTACT_DEPTH and (worst is None or c.dist < worst[0]):
            worst = (float(c.dist), g1, g2)
    if worst is None:
        return Finding("home_contacts", "pass", "no contact at home (gripper open)")
    depth, g1, g2 = worst
    if int(m.geom_bodyid[g1]) not in bench.moving:
        g1, g2 = g2, g1
    measured = (
        f"at home {_geom_name(m, g1)} touches {_geom_name(m, g2)} ({-depth * 1000:.0f} mm deep)"
    )
    fix = "give arm.home a posture whose links and open fingers clear the table and objects"
    return Finding("home_contacts", "fail", measured, fix)


def check_home_view(bench: _Bench, postures: Postures | None) -> Finding:
    """``home_view``: for each object, the share of the image region where its range lies
    (:func:`~smccli.world.robot_view.range_corners`) that the arm's bounding spheres cover
    at home, seen through the scene's camera; the links only the first joint moves are
    left out (a turret stays at the base in any home posture)."""
    scene = bench.scene
    if scene is None:
        return Finding("home_view", "skip", "no scene (give --scene for its camera)")
    if bench.robot.base is not None:
        return Finding("home_view", "skip", "a mobile base: its camera rides with it")
    _home_open(bench, postures)
    m, d = bench.model, bench.data
    camera = PinholeView(m, d, scene)
    joints = bench.robot.arm_joints
    second = int(m.jnt_bodyid[m.joint(joints[1] if len(joints) > 1 else joints[0]).id])
    centers, radii = link_spheres(m, d, subtree_bodies(m, [second]))
    shares = []
    for obj in scene.objects:
        region, far = camera.region(range_corners(obj))
        if region.any():
            covered = camera.cover(centers, radii, far)
            shares.append((float((covered & region).sum() / region.sum()), obj.name))
    if not shares:
        return Finding("home_view", "skip", f"no object in camera {scene.camera.name}'s view")
    share, name = max(shares)
    seen = f"camera {scene.camera.name}'s image"
    measured = f"at home the arm covers {share:.1%} of where {name} lies in {seen}"
    if share > VIEW_SHARE:
        fix = (
            "give arm.home a posture out of the camera's view of the objects (turn the first "
            "joint away from them, or fold the arm above and behind its base)"
        )
        return Finding("home_view", "fail", measured, fix)
    return Finding("home_view", "pass", measured)


# --- reach ------------------------------------------------------------------------------


def reach_targets(scene: Scene) -> list[tuple[str, np.ndarray]]:
    """Places to reach, gripper down: each object's range on a grid of REACH_GRID values
    per randomised dimension (fewer when the objects are many: REACH_BUDGET in all), the
    POI at the object's centre (a container's or a scale's: PLACE_ABOVE its top)."""
    objects = [o for o in scene.objects if o.on is None]
    n = REACH_GRID
    while n > 2 and sum(n ** _dims(o) for o in objects) > REACH_BUDGET:
        n -= 1
    targets = []
    for o in objects:
        if o.shape in ("open_box", "scale"):
            z = o.pose[2] + o.size[2] / 2 + PLACE_ABOVE
        else:
            z = max(o.pose[2], MIN_Z + 1e-3)
        for x in _samples(o.range_x, n):
            for y in _samples(o.range_y, n):
                for yaw in _samples(o.range_yaw, n):
                    targets.append((o.name, np.array([x, y, z, yaw])))
    return targets


def _dims(o: ObjectSpec) -> int:
    return sum(r[0] != r[1] for r in (o.range_x, o.range_y, o.range_yaw))


def _samples(r: tuple[float, float], n: int) -> np.ndarray:
    return np.linspace(r[0], r[1], n if r[0] != r[1] else 1)


def check_reach(bench: _Bench) -> Finding:
    """``reach``: the share of :func:`reach_targets` the IK reaches (a target's yaw or its
    half turn), and the worst one missed."""
    scene = bench.scene
    if scene is None:
        return Finding("reach", "skip", "no scene (give --scene for its object ranges)")
    if bench.robot.base is not None:
        return Finding("reach", "skip", "a mobile base brings its arm to the objects")
    targets = reach_targets(scene)
    controller = CartesianController(bench.model, bench.robot)
    anchor, radius = arm_reach(bench.model, bench.robot)
    missed: list[tuple[float, str, np.ndarray]] = []
    for name, target in targets:
        beyond = float(np.linalg.norm(target[:3] - anchor)) - radius
        if beyond > 0:  # past the chain's length, no IK needed; ranked past any IK miss
            missed.append((beyond + 1.0, name, target))
            continue
        miss = _miss(controller, target)
        if miss is not None:
            missed.append((miss, name, target))
    share = 1.0 - len(missed) / len(targets)
    measured = (
        f"{share:.0%} of {len(targets)} places over the objects' ranges reached, gripper down"
    )
    if not missed:
        return Finding("reach", "pass", measured)
    _, name, t = max(missed, key=lambda x: x[0])
    why = reach_problem(bench.model, bench.robot, t) or "the IK does not converge"
    measured += (
        f"; worst: {name} at ({t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f}) m, yaw {t[3]:.2f} rad: {why}"
    )
    fix = f"narrow {name}'s range in the scene file to where the arm reaches"
    return Finding("reach", "fail", measured, fix)


def _miss(controller: CartesianController, target: np.ndarray) -> float | None:
    """None when the IK reaches ``target`` at its yaw or at the half turn (a parallel
    gripper's symmetry), else by how much it misses: position [m] + 0.01 x orientation
    [rad]. Two solves at most, one when the position stays over 1 cm short (the half turn
    changes only the orientation)."""
    worst = math.inf
    for turn in (0.0, math.pi):
        t = target + np.array([0.0, 0.0, 0.0, turn])
        controller.reset(controller.home)
        q, ok = controller.solve(t)
        if ok:
            return None
        e = controller.error(q, t)
        pos = float(np.linalg.norm(e[:3]))
        worst = min(worst, pos + 0.01 * float(np.linalg.norm(e[3:])))
        if pos > 0.01:
            break
    return worst


# --- the POI ----------------------------------------------------------------------------


def check_poi(bench: _Bench, postures: Postures | None, gripper_ok: bool) -> Finding:
    """``poi``: the POI between the pads at the open posture (and, two fingers closed,
    where they meet), in the site's frame: y the finger travel, z the approach."""
    if postures is None:
        return Finding("poi", "skip", "no gripper")
    if not gripper_ok:
        return Finding("poi", "skip", "the gripper does not open and close (see gripper)")
    sides = _pads(bench, postures.open)
    if len(sides) != 2:
        return Finding("poi", "skip", "not two pads (fingers with no contact geoms)")
    site = repr(bench.robot.poi)
    a, b, near = _pad_boxes(bench, sides)
    names = [_geom_name(bench.model, s[0]) for s in sides]
    # One jaw holds an object against the fixed one (the hand's, sides[1]): the POI may
    # lie POI_HOLD from it however wide the jaw opens.
    if a[:, 1].mean() > b[:, 1].mean():
        a, b, names = b, a, names[::-1]
        fixed = 0
    else:
        fixed = 1
    low, high = a[1, 1], b[0, 1]  # inner faces, along the site's y
    gap = high - low
    need = [POI_SHARE * gap] * 2
    if len(bench.finger_j) == 1:
        need[fixed] = min(need[fixed], POI_HOLD)
    measured = (
        f"open, the POI is {-low * 1000:.0f} mm from pad {names[0]} and {high * 1000:.0f} mm "
        f"from pad {names[1]} along its y (gap {gap * 1000:.0f} mm)"
    )
    middle = (low + high) / 2
    if near and (gap <= 0 or -low < need[0] or high < need[1]):
        fix = f"move site {site} {middle * 1000:+.0f} mm along its y axis, between the pads"
        return Finding("poi", "fail", measured, fix)
    lo = np.maximum(a[0], b[0]) - POI_TOLERANCE
    hi = np.minimum(a[1], b[1]) + POI_TOLERANCE
    for axis, what in ((2, "approach (z)"), (0, "width (x)")):
        if not lo[axis] <= 0.0 <= hi[axis]:
            off = lo[axis] if lo[axis] > 0 else hi[axis]
            measured += f"; {abs(off) * 1000:.0f} mm outside the pads along its {what}"
            fix = (
                f"move site {site} {off * 1000:+.0f} mm along its {what[-2]} axis, within the pads"
            )
            hinged = (bench.model.jnt_type[bench.finger_j] == mujoco.mjtJoint.mjJNT_HINGE).any()
            if not near and hinged:
                fix += ", or open the gripper less (gripper.opening): a hinged jaw swings back"
            return Finding("poi", "fail", measured, fix)
    sides = _pads(bench, postures.closed)
    if len(bench.finger_j) >= 2 and len(sides) == 2:
        ca, cb, _ = _pad_boxes(bench, sides)
        meet = (min(ca[1, 1], cb[1, 1]) + max(ca[0, 1], cb[0, 1])) / 2
        if abs(meet) > POI_SHARE * gap:
            measured += f"; closed, the pads meet {meet * 1000:+.0f} mm from it"
            fix = f"move site {site} {meet * 1000:+.0f} mm along its y axis, where the pads meet"
            return Finding("poi", "fail", measured, fix)
    return Finding("poi", "pass", measured)
