"""``smc robots import``: the gripper found in the composed model (joints, actuator,
commands found by driving it in simulation, the POI between the pads); see
:mod:`smccli.world.robot_import`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from smccli.world.robot_compose import Frame
from smccli.world.robot_import_arm import (
    PINCH_SITE,
    PREFIX,
    SETTLE,
    ArmFound,
    Guess,
    actuators_on,
    bad_file,
    compose,
    flow,
    name_of,
)
from smccli.world.robot_model import subtree_bodies

PAD_DEPTH = 0.04
"""The stretch of a finger next to its tip that grips, along the approach [m]: its middle,
2 cm from the tip, is where the hand-written built-in robots put their POI within 5 mm
(the arm and six 1.5 cm from their 9 cm fingers' tips, the Panda at its 4.5 cm pads'
centre)."""
SITE_NEAR = 0.03
"""A pinch site this near the pads' midpoint is the POI [m]."""


@dataclass(frozen=True, slots=True)
class HandFound:
    """The gripper as found in the composed model."""

    joints: list[str]
    actuator: str
    couple: tuple[tuple[str, str, float], ...]
    commands: tuple[float, float]
    opening: tuple[float, float]
    poi_at: str
    poi: Frame


def _finger_joints(m: mujoco.MjModel, arm: ArmFound, separate: bool) -> set[int]:
    last = int(m.jnt_bodyid[m.joint(arm.names[-1]).id])
    below = subtree_bodies(m, [last])
    kinds = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    return {
        j
        for j in range(m.njnt)
        if int(m.jnt_bodyid[j]) in below
        and int(m.jnt_type[j]) in kinds
        and name_of(m, mujoco.mjtObj.mjOBJ_JOINT, j) not in arm.names
        and (not separate or name_of(m, mujoco.mjtObj.mjOBJ_JOINT, j).startswith(PREFIX))
    }


def _ratio(m: mujoco.MjModel, joint: int, to: int) -> float:
    """How ``joint`` follows ``to``: -1 where their ranges mirror, else the ratio of spans."""
    (a0, a1), (b0, b1) = m.jnt_range[joint], m.jnt_range[to]
    if abs(a0 + b1) < 1e-6 and abs(a1 + b0) < 1e-6:
        return -1.0
    return float((a1 - a0) / (b1 - b0)) if b1 != b0 else 1.0


def _drive(
    m: mujoco.MjModel, hold: tuple[np.ndarray, np.ndarray, np.ndarray], act: int, command: float
) -> np.ndarray:
    """The whole qpos after driving actuator ``act`` at ``command`` for SETTLE seconds, the
    arm held where ``hold`` = (its qpos addresses, dof addresses, values) puts it."""
    adr, dof, arm_q = hold
    d = mujoco.MjData(m)
    d.qpos[adr] = arm_q
    d.ctrl[act] = command
    for _ in range(int(SETTLE / m.opt.timestep)):
        d.qpos[adr], d.qvel[dof] = arm_q, 0.0
        mujoco.mj_step(m, d)
    d.qpos[adr] = arm_q
    return d.qpos.copy()


def _collides(m: mujoco.MjModel, g: int) -> bool:
    return bool(m.geom_contype[g] or m.geom_conaffinity[g])


def _pad_point(m: mujoco.MjModel, d: mujoco.MjData, g: int, a: np.ndarray) -> np.ndarray:
    """Where a geom grips, its last PAD_DEPTH along the approach ``a`` [m] (world frame):
    a mesh's vertices there, averaged; a primitive's centre moved out to the middle of
    that stretch (a long finger grips near its tip, a short pad at its centre)."""
    mesh = int(m.geom_dataid[g])
    xmat = d.geom_xmat[g].reshape(3, 3)
    if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH and mesh >= 0:
        adr, n = int(m.mesh_vertadr[mesh]), int(m.mesh_vertnum[mesh])
        p = d.geom_xpos[g] + m.mesh_vert[adr : adr + n] @ xmat.T
        depth = p @ a
        return p[depth >= depth.max() - PAD_DEPTH].mean(axis=0)
    reach = float(np.abs(xmat.T @ a) @ m.geom_aabb[g, 3:])  # centre to tip along a
    return d.geom_xpos[g] + a * max(0.0, reach - PAD_DEPTH / 2)


def _tip_depth(m: mujoco.MjModel, d: mujoco.MjData, g: int, a: np.ndarray) -> float:
    """How far along ``a`` a geom reaches (its bounding box's extent) [m]."""
    xmat = d.geom_xmat[g].reshape(3, 3)
    centre = d.geom_xpos[g] + xmat @ m.geom_aabb[g, :3]
    return float(centre @ a + np.abs(xmat.T @ a) @ m.geom_aabb[g, 3:])


def _tip(
    m: mujoco.MjModel, d: mujoco.MjData, side: list[int], a: np.ndarray
) -> tuple[int, np.ndarray]:
    """The side's geom reaching furthest along the approach ``a`` and its pad point."""
    g = max(side, key=lambda k: _tip_depth(m, d, k, a))
    return g, _pad_point(m, d, g, a)


def _reach(m: mujoco.MjModel, d: mujoco.MjData, g: int, a: np.ndarray) -> float:
    """How far along ``a`` a geom reaches: a mesh's furthest vertex, else its box [m]."""
    if m.geom_type[g] != mujoco.mjtGeom.mjGEOM_MESH or int(m.geom_dataid[g]) < 0:
        return _tip_depth(m, d, g, a)
    return float((_points(m, d, g) @ a).max())


def _points(m: mujoco.MjModel, d: mujoco.MjData, g: int) -> np.ndarray:
    """A geom's mesh vertices, else its bounding box's corners (world frame) [m]."""
    mesh = int(m.geom_dataid[g])
    if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH and mesh >= 0:
        adr, n = int(m.mesh_vertadr[mesh]), int(m.mesh_vertnum[mesh])
        local = m.mesh_vert[adr : adr + n]
    else:
        corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
        local = m.geom_aabb[g, :3] + m.geom_aabb[g, 3:] * corners
    return d.geom_xpos[g] + local @ d.geom_xmat[g].reshape(3, 3).T


def _between_faces(
    m: mujoco.MjModel,
    d: mujoco.MjData,
    pads: list[tuple[int, np.ndarray]],
    a: np.ndarray,
    u: np.ndarray,
) -> tuple[list[tuple[int, np.ndarray]], float]:
    """The pad points moved along the finger travel (``u`` across the approach ``a``) so
    that their midpoint lies midway between the pads' inner faces (their points within
    PAD_DEPTH / 2 of it along ``a``): a jaw's points average its thickness, which differs
    from the fixed jaw's. And the gap between the faces [m] (inf where a pad has no point
    there: the points are then kept)."""
    mid = (pads[0][1] + pads[1][1]) / 2
    y = u - (u @ a) * a
    y /= np.linalg.norm(y)
    faces = []
    for g, point in pads:
        p = _points(m, d, g)
        p = p[np.abs((p - mid) @ a) <= PAD_DEPTH / 2]
        if not len(p):
            return pads, float("inf")
        along = (p - mid) @ y
        faces.append(along.min() if (point - mid) @ y > 0 else along.max())
    shift = y * float(np.mean(faces))
    return [(g, point + shift) for g, point in pads], float(abs(faces[0] - faces[1]))


def _facing_share(
    m: mujoco.MjModel,
    data: list[mujoco.MjData],
    closed_i: int,
    sides: tuple[list[int], list[int]],
    fingers: set[int],
    a: np.ndarray,
) -> float:
    """The largest share (in steps of 1/40) of a one-jaw gripper's closed-to-open travel at
    which the moving jaw's tip stays within PAD_DEPTH / 4 of the fixed jaw's along the
    approach ``a``: a hinged jaw that swings further back no longer grips across its POI."""
    moving, fixed = sides
    adr = np.array([m.jnt_qposadr[j] for j in sorted(fingers)], dtype=int)
    q0, q1 = data[closed_i].qpos[adr], data[1 - closed_i].qpos[adr]
    d = mujoco.MjData(m)
    d.qpos[:] = data[closed_i].qpos
    mujoco.mj_kinematics(m, d)
    tip = max(_reach(m, d, g, a) for g in fixed) - PAD_DEPTH / 4
    share = 0.0
    for t in np.linspace(0.0, 1.0, 41):
        d.qpos[adr] = q0 + t * (q1 - q0)
        mujoco.mj_kinematics(m, d)
        if max(_reach(m, d, g, a) for g in moving) < tip:
            break
        share = float(t)
    return share if share > 0.0 else 1.0


def _drive_ends(
    m: mujoco.MjModel, arm: ArmFound, act: int, ends: list[float] | tuple[float, ...]
) -> list[mujoco.MjData]:
    """The gripper driven to each end of ``ends``, the arm held at zero (clipped to its
    limits), without gravity: the settled states (kinematics computed)."""
    ids = [m.joint(n).id for n in arm.names]
    adr = np.array([m.jnt_qposadr[j] for j in ids], dtype=int)
    dof = np.array([m.jnt_dofadr[j] for j in ids], dtype=int)
    lo, hi = m.jnt_range[ids].T
    hold = (adr, dof, np.clip(0.0, lo, hi))
    m.opt.gravity[:] = 0.0
    out = []
    for c in ends:
        d = mujoco.MjData(m)
        d.qpos[:] = _drive(m, hold, act, c)
        mujoco.mj_forward(m, d)
        out.append(d)
    return out


def _driven(m: mujoco.MjModel, act: int) -> tuple[list[int], str]:
    """The joints actuator ``act`` moves (its joint, or its tendon's) and how it says so."""
    if m.actuator_trntype[act] == mujoco.mjtTrn.mjTRN_JOINT:
        j = int(m.actuator_trnid[act, 0])
        return [j], f"joint {name_of(m, mujoco.mjtObj.mjOBJ_JOINT, j)!r}"
    t = int(m.actuator_trnid[act, 0])
    adr, n = int(m.tendon_adr[t]), int(m.tendon_num[t])
    joints = [int(m.wrap_objid[w]) for w in range(adr, adr + n)]
    return joints, f"tendon {name_of(m, mujoco.mjtObj.mjOBJ_TENDON, t)!r}"


def _find_actuator(
    m: mujoco.MjModel, arm: ArmFound, gripper: Path | None, source: Path
) -> tuple[int, list[tuple[str, str, float]]]:
    """The gripper's actuator and the fingers to couple to its joint (those driven by an
    actuator of their own)."""
    fingers = _finger_joints(m, arm, gripper is not None)
    acts = actuators_on(m, fingers)
    if not fingers or not acts:
        what = "no finger joint" if not fingers else "no actuator on its finger joints"
        hint = "" if gripper is not None else "; give the gripper's own file with --gripper"
        raise bad_file(source, f"{what} below the arm's flange (no gripper found){hint}")
    couple = []
    for other in acts[1:]:
        if m.actuator_trntype[other] == mujoco.mjtTrn.mjTRN_JOINT:
            j, to = int(m.actuator_trnid[other, 0]), int(m.actuator_trnid[acts[0], 0])
            name = lambda k: name_of(m, mujoco.mjtObj.mjOBJ_JOINT, k)  # noqa: E731
            couple.append((name(j), name(to), _ratio(m, j, to)))
    return acts[0], couple


def _sides(
    m: mujoco.MjModel,
    fingers: set[int],
    hand: set[int],
    data: list[mujoco.MjData],
    source: Path,
) -> tuple[list[int], list[int], np.ndarray, list[int]]:
    """The two sides' collision geoms (those the finger joints move, split by the way they
    move between the two states ``data``; a one-jaw gripper's second side the hand's own),
    the finger travel's direction, and every geom the finger joints move."""
    moving = subtree_bodies(m, [int(m.jnt_bodyid[j]) for j in fingers])
    geoms = [g for g in range(m.ngeom) if int(m.geom_bodyid[g]) in moving and _collides(m, g)]
    if not geoms:
        raise bad_file(source, "its fingers have no collision geoms (no pads to grip with)")
    disp = np.array([data[1].geom_xpos[g] - data[0].geom_xpos[g] for g in geoms])
    u = np.linalg.svd(disp)[2][0]
    sign = disp @ u
    side_a = [g for g, s in zip(geoms, sign, strict=True) if s > 1e-4]
    side_b = [g for g, s in zip(geoms, sign, strict=True) if s < -1e-4]
    if not side_a or not side_b:  # the fixed jaw: the hand's own collision geoms
        side_a = side_a or side_b
        side_b = [
            g for g in range(m.ngeom) if int(m.geom_bodyid[g]) in hand - moving and _collides(m, g)
        ]
        if not side_b:
            raise bad_file(
                source, "one finger moves and the hand has no collision geom to grip against"
            )
    return side_a, side_b, u, geoms


def read_hand(arm: ArmFound, gripper: Path | None, where: Path, guesses: list[Guess]) -> HandFound:
    """The gripper's joints, actuator, commands and POI, found in the composed model."""
    source = gripper or arm.path
    m = compose(arm, gripper, where).compile()
    act, couple = _find_actuator(m, arm, gripper, source)
    act_name = name_of(m, mujoco.mjtObj.mjOBJ_ACTUATOR, act)
    if couple:  # the coupled fingers' actuators are left out: ids change
        m = compose(arm, gripper, where, couple=tuple(couple)).compile()
        act = m.actuator(act_name).id
    driven, through = _driven(m, act)
    lo, hi = m.actuator_ctrlrange[act] if m.actuator_ctrllimited[act] else m.jnt_range[driven[0]]
    ends = [float(lo), float(hi)]
    data = _drive_ends(m, arm, act, ends)
    qa = [d.qpos[[m.jnt_qposadr[j] for j in driven]] for d in data]
    travel = qa[1] - qa[0]
    joints = [j for j, t in zip(driven, travel, strict=True) if abs(t) > 0.5 * abs(travel[0])]
    fingers = _finger_joints(m, arm, gripper is not None)
    last = m.joint(arm.names[-1]).id
    hand = subtree_bodies(m, [int(m.jnt_bodyid[last])])
    side_a, side_b, u, geoms = _sides(m, fingers, hand, data, source)
    one_jaw = not set(side_b) & set(geoms)
    d0 = data[0]
    a = d0.xaxis[last].copy()
    if (np.mean([d0.geom_xpos[g] for g in geoms], axis=0) - d0.xanchor[last]) @ a < 0:
        a = -a
    pads = [[_tip(m, d, s, a) for s in (side_a, side_b)] for d in data]
    gaps = [
        float(np.linalg.norm((p[0][1] - p[1][1]) - ((p[0][1] - p[1][1]) @ a) * a)) for p in pads
    ]
    closed_i = int(np.argmin(gaps))
    open_i = 1 - closed_i
    ends_seen = tuple(ends)
    if one_jaw:  # a hinged jaw swung past the fixed one's tip no longer faces it
        share = _facing_share(m, data, closed_i, (side_a, side_b), fingers, a)
        if share < 1.0:
            ends[open_i] = ends[closed_i] + share * (ends[open_i] - ends[closed_i])
            data[open_i] = _drive_ends(m, arm, act, (ends[open_i],))[0]
            qa[open_i] = data[open_i].qpos[[m.jnt_qposadr[j] for j in driven]]
            pads[open_i] = [_tip(m, data[open_i], s, a) for s in (side_a, side_b)]
    commands = (ends[closed_i], ends[open_i])
    opening = (float(qa[closed_i][0]), float(qa[open_i][0]))
    guesses += _hand_guesses(
        m, (act_name, through, couple, joints[0]), ends_seen, commands, opening, gaps
    )
    # Closed, the tips reach furthest (a hinged jaw swings out open): the pads there; one
    # jaw holds an object against the other, the middle of the open gap.
    at_i = open_i if one_jaw else closed_i
    at_pads, near = pads[at_i], SITE_NEAR
    if one_jaw:  # a site nearer one jaw than a quarter of the gap would fail smc robots
        at_pads, gap = _between_faces(m, data[at_i], pads[at_i], a, u)
        near = min(near, gap / 4)
    at, poi = _poi(m, data[at_i], at_pads, a, u, (hand, near), arm.names[-1], guesses)
    names = [name_of(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in joints]
    return HandFound(names, act_name, tuple(couple), commands, opening, at, poi)


def _hand_guesses(
    m: mujoco.MjModel,
    found: tuple[str, str, list[tuple[str, str, float]], int],
    ends_seen: tuple[float, ...],
    commands: tuple[float, float],
    opening: tuple[float, float],
    gaps: list[float],
) -> list[Guess]:
    """What :func:`read_hand` guessed about the actuator (``found`` = its name, what it
    drives through, the coupled fingers, the first finger joint) and its commands."""
    act_name, through, couple, joint = found
    coupled = (
        "; coupled: " + ", ".join(f"{j} = {r:g} x {t}" for j, t, r in couple) if couple else ""
    )
    jname = name_of(m, mujoco.mjtObj.mjOBJ_JOINT, joint)
    return [
        Guess(
            "gripper.actuator",
            act_name,
            f"it drives the finger joints (through {through}){coupled}",
        ),
        Guess(
            "gripper.commands",
            flow(commands),
            f"driven to {ends_seen[0]:g} and {ends_seen[1]:g} for {SETTLE:g} s: the pads "
            f"{gaps[0] * 1000:.0f} and {gaps[1] * 1000:.0f} mm apart; the wider end opens"
            + (
                f", as far as {commands[1]:g} (the jaw's tip stays within "
                f"{PAD_DEPTH / 4 * 1000:.0f} mm of the fixed jaw's along the approach)"
                if commands[1] not in ends_seen
                else ""
            ),
        ),
        Guess(
            "gripper.opening",
            flow([round(v, 4) for v in opening]),
            f"{jname} settled there (closed, open)",
        ),
    ]


def _poi(
    m: mujoco.MjModel,
    d: mujoco.MjData,
    pads: list[tuple[int, np.ndarray]],
    a: np.ndarray,
    u: np.ndarray,
    within: tuple[set[int], float],
    roll: str,
    guesses: list[Guess],
) -> tuple[str, Frame]:
    """The POI: the gripper's pinch site near the pads' midpoint (``within`` = the hand's
    bodies, how near [m]), else that midpoint (in the hand's body); z along the approach
    ``a``, y along the finger travel ``u``."""
    hand, near = within
    mid = (pads[0][1] + pads[1][1]) / 2
    y = u - (u @ a) * a
    y /= np.linalg.norm(y)
    sites = sorted(
        (
            s
            for s in range(m.nsite)
            if PINCH_SITE.search(name_of(m, mujoco.mjtObj.mjOBJ_SITE, s))
            and int(m.site_bodyid[s]) in hand
            and np.linalg.norm(d.site_xpos[s] - mid) < near
        ),
        key=lambda s: (len(name_of(m, mujoco.mjtObj.mjOBJ_SITE, s)), s),
    )
    if sites:
        at = name_of(m, mujoco.mjtObj.mjOBJ_SITE, sites[0])
        p_at, r_at = d.site_xpos[sites[0]], d.site_xmat[sites[0]].reshape(3, 3)
        point = p_at
        off = np.linalg.norm(p_at - mid) * 1000
        why = f"the gripper's own site {at!r}, {off:.0f} mm from the pads' midpoint"
    else:
        body = int(m.jnt_bodyid[m.joint(roll).id])
        at = name_of(m, mujoco.mjtObj.mjOBJ_BODY, body)
        p_at, r_at = d.xpos[body], d.xmat[body].reshape(3, 3)
        point = mid
        pad = [
            name_of(m, mujoco.mjtObj.mjOBJ_GEOM, g)
            or f"a geom of body {name_of(m, mujoco.mjtObj.mjOBJ_BODY, int(m.geom_bodyid[g]))}"
            for g, _ in pads
        ]
        why = f"the midpoint of the pads nearest the fingertips ({pad[0]}, {pad[1]})"
    rel = r_at.T @ np.column_stack([np.cross(y, a), y, a])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, rel.ravel())
    pos = r_at.T @ (point - p_at)
    frame = Frame(
        tuple(round(float(v), 4) + 0.0 for v in pos),  # type: ignore[arg-type]
        tuple(round(float(v), 6) + 0.0 for v in quat),  # type: ignore[arg-type]
    )
    why += f"; z along {roll}'s axis out of the fingers, y along the finger travel"
    guesses.append(Guess("poi", f"at {at}, pos {flow(frame.pos)}", why))
    return at, frame
