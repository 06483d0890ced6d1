"""``smc robots import``: a robot file drafted from a vendor's arm (MJCF or URDF) and an
optional separate gripper (MJCF), never editing them (issue 37).

Each guess is data (:class:`Guess`: what, value, why); :func:`draft_robot` returns them
with the robot file's text (:mod:`smccli.world.robot_import_arm` reads the arm,
:mod:`smccli.world.robot_import_hand` the gripper, this module finds home and writes the
file). What it guesses, in order:

- the arm chain: the longest chain of hinge joints from the root, joints named like a
  finger (grip, finger, jaw, claw) left to the gripper; the flange: the last arm body's
  joint-less descendant (robosuite's ``right_hand``) where a separate gripper attaches;
- the arm's actuators by transmission (a joint of the chain); torque motors (no bias) get
  ``arm.servo`` with docs/robots.md's gains scaled to the arm's moving mass;
- the gripper's actuator (joint or tendon transmission on the gripper's joints), a second
  finger with its own actuator coupled to the first (``gripper.couple``);
- its commands: the actuator driven to each end of its ``ctrlrange`` in simulation until
  the fingers settle; the end where the pads' tips end further apart opens
  (``gripper.commands`` in the actuator's units, ``opening`` the finger joint's positions);
  a one-jaw gripper opens only as far as its jaw's tip stays within a quarter of the
  gripping stretch of the fixed jaw's (a hinged jaw swings back past it);
- the POI: the gripper's own pinch site (a site named like grip, pinch or tcp) or the
  midpoint of the pads nearest the fingertips, closed (one jaw: midway between the jaws'
  inner faces, open, a pinch site only within a quarter of that gap); z along the wrist
  roll's axis out of the fingers, y along the finger travel;
- a mount where the first joint's axis is not at the origin or the arm does not reach
  along +x at zero (the controller's convention);
- home: the gripper pointing down above the table in front of the base, elbow up, by
  least squares (scipy) on the composed model's kinematics from several seeds, keeping the
  posture whose joints sit highest: the controller's IK
  (:meth:`~smccli.world.controller.CartesianController.solve`) starts from a home, which is
  what is sought here, and settles on one branch. The draft then goes through
  :func:`~smccli.world.robot_checks.simulation_checks` (contacts at home; in a scene the
  camera's view of the objects and the controller's reach).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import mujoco
import numpy as np
from scipy.optimize import least_squares

from smccli.errors import SceneError
from smccli.outputs import check_output, write_atomic
from smccli.world.robot_compose import POI_SITE, PoiPlacement
from smccli.world.robot_import_arm import (
    HOME_PLACES,
    ArmFound,
    Draft,
    Guess,
    compose,
    flow,
    read_arm,
)
from smccli.world.robot_import_hand import HandFound, read_hand

SEEDS = 12
"""Starting postures tried for home (the reference posture, mid-range, then random)."""


def home_posture(arm: ArmFound, m: mujoco.MjModel, guesses: list[Guess]) -> list[float]:
    """The gripper pointing down (POI x along +x) in front of the first joint and above
    the table (the first of HOME_PLACES it reaches), elbow up."""
    ids = [m.joint(n).id for n in arm.names]
    adr = np.array([m.jnt_qposadr[j] for j in ids])
    lo, hi = m.jnt_range[ids].T.copy()
    free = ~m.jnt_limited[ids].astype(bool)
    lo[free], hi[free] = -np.pi, np.pi
    d = mujoco.MjData(m)
    site = m.site(POI_SITE).id
    mujoco.mj_kinematics(m, d)
    anchor = d.xanchor[ids[0]].copy()
    top = int(m.jnt_bodyid[ids[0]])
    reach = float(np.linalg.norm(m.site_pos[site]))  # the chain's length bounds the reach
    b = int(m.site_bodyid[site])
    while b not in (top, 0):
        reach += float(np.linalg.norm(m.body_pos[b]))
        b = int(m.body_parentid[b])
    q = None
    for ahead, up in HOME_PLACES:
        target = np.array([anchor[0] + ahead * reach, anchor[1], up * reach])
        q = _home_at(m, d, (adr, site, ids), (lo, hi), target)
        if q is not None:
            break
    if q is None:
        q = np.clip(0.0, lo, hi)
        why = "no posture found with the gripper down in front of the base: zero (edit it)"
    else:
        why = (
            f"the gripper down {ahead * reach:.2f} m in front of the first joint and "
            f"{up * reach:.2f} m above the table ({ahead:g} and {up:g} of the chain's length "
            f"{reach:.2f} m), elbow up (the highest of {SEEDS} solutions)"
        )
    home = [round(float(v), 4) for v in q]
    guesses.append(Guess("arm.home", flow(home), why))
    return home


def _home_at(
    m: mujoco.MjModel,
    d: mujoco.MjData,
    where: tuple[np.ndarray, int, list[int]],
    bounds: tuple[np.ndarray, np.ndarray],
    target: np.ndarray,
) -> np.ndarray | None:
    """The converged posture with the gripper down at ``target`` whose joints sit highest
    (elbow up), or None."""
    (adr, site, ids), (lo, hi) = where, bounds
    mid = (lo + hi) / 2

    def residual(q: np.ndarray) -> np.ndarray:
        d.qpos[adr] = q
        mujoco.mj_kinematics(m, d)
        r = d.site_xmat[site].reshape(3, 3)
        return np.concatenate(
            [
                d.site_xpos[site] - target,
                r[:, 2] - [0, 0, -1],
                0.3 * (r[:, 0] - [1, 0, 0]),
                0.01 * (q - mid),
            ]
        )

    rng = np.random.default_rng(0)
    seeds = [np.clip(0.0, lo, hi), mid] + [rng.uniform(lo, hi) for _ in range(SEEDS - 2)]
    best: tuple[float, np.ndarray] | None = None
    for seed in seeds:
        sol = least_squares(residual, seed, bounds=(lo, hi))
        res = residual(sol.x)
        if np.linalg.norm(res[:3]) > 2e-3 or np.linalg.norm(res[3:6]) > 0.03:
            continue
        q = sol.x - 2 * np.pi * np.round(sol.x / (2 * np.pi))  # the turn nearest zero
        q = np.where((q >= lo) & (q <= hi), q, sol.x)
        height = float(np.mean(d.xanchor[ids[1:-1], 2]))
        if best is None or height > best[0] + 1e-3:
            best = (height, q)
    return None if best is None else best[1]


def _rel(path: Path, folder: Path) -> str:
    return os.path.relpath(path.resolve(), folder.resolve())


def robot_text(
    name: str, arm: ArmFound, gripper: Path | None, hand: HandFound, home: list[float], folder: Path
) -> str:
    """The robot file's YAML (flow lists, comments saying it is a draft)."""
    key = "urdf" if arm.path.suffix.lower() == ".urdf" else "mjcf"
    lines = [
        "# Drafted by `smc robots import` from the vendor's files as they are: check each",
        "# guess it printed, then `smc robots` this file (and --scene your scene).",
        f"name: {name}",
        f'description: "{name}, imported from {arm.path.name}'
        + (f" with {gripper.name}" if gripper else "")
        + '"',
        f"{key}: {_rel(arm.path, folder)}",
    ]
    if arm.mount is not None:
        lines.append(f"mount: {{pos: {flow(arm.mount.pos)}, quat: {flow(arm.mount.quat)}}}")
    lines += ["arm:", f"  joints: {flow(arm.names)}"]
    if arm.servo is not None:
        lines.append(f"  servo: {{kp: {flow(list(arm.servo.kp))}}}")
    else:
        lines.append(f"  actuators: {flow(arm.actuators)}")
    lines.append(f"  home: {flow(home)}")
    lines.append(
        f"poi: {{at: {hand.poi_at}, pos: {flow(hand.poi.pos)}, quat: {flow(hand.poi.quat)}}}"
    )
    lines.append("gripper:")
    if gripper is not None:
        lines += [f"  mjcf: {_rel(gripper, folder)}", f"  attach: {arm.flange}"]
        if hand.couple:
            pairs = ", ".join(
                f"{{joint: {a}, to: {b}, ratio: {flow(r)}}}" for a, b, r in hand.couple
            )
            lines.append(f"  couple: [{pairs}]")
    lines += [
        f"  joints: {flow(hand.joints)}",
        f"  actuator: {hand.actuator}",
        f"  opening: {flow([round(v, 4) for v in hand.opening])}",
    ]
    (c0, c1), (q0, q1) = hand.commands, hand.opening
    if max(abs(c0 - q0), abs(c1 - q1)) > 0.05 * abs(q1 - q0):  # not in the joint's units
        lines.append(f"  commands: {flow(list(hand.commands))}")
    return "\n".join(lines) + "\n"


def draft_robot(
    arm_file: Path, gripper: Path | None, out_dir: Path, name: str | None = None
) -> Draft:
    """The robot file drafted for ``arm_file`` (and ``gripper``), its paths relative to
    ``out_dir``; SceneError naming the file on bad input."""
    where = out_dir / "robot.yaml"
    guesses: list[Guess] = []
    arm = read_arm(arm_file, where, guesses)
    hand = read_hand(arm, gripper, where, guesses)
    poi = PoiPlacement(hand.poi_at, hand.poi)
    m = compose(arm, gripper, where, couple=hand.couple, poi=poi).compile()
    home = home_posture(arm, m, guesses)
    groups = sorted({int(g) for g in m.geom_group})
    guesses.append(
        Guess("geom groups", flow(groups), "as the model has them (none given: smc reads them)")
    )
    text = robot_text(name or out_dir.name, arm, gripper, hand, home, out_dir)
    return Draft(text, tuple(guesses))


def write_draft(draft: Draft, out_dir: Path, *, force: bool) -> Path:
    """DIR/robot.yaml written atomically (OutputExistsError without ``force``)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    path = check_output(out_dir / "robot.yaml", force=force)
    return write_atomic(path, draft.text)


def scene_text(scene_ref: str, out_dir: Path) -> str:
    """A copy of the scene file ``scene_ref`` (a built-in name or a path) for DIR: its
    ``robot:`` the drafted ``robot.yaml`` beside it, its ``mjcf:`` the scene's own MJCF
    (relative to DIR); the rest, comments included, as written."""
    from smccli.world.scene import SCENES_DIR, builtin_names
    from smccli.world.scene_file import read_scene_yaml

    path = (
        SCENES_DIR / scene_ref / "scene.yaml" if scene_ref in builtin_names() else Path(scene_ref)
    )
    if not path.is_file():
        raise SceneError(f"{scene_ref}: no such scene (a built-in name or a scene.yaml)")
    text = path.read_text()
    raw = read_scene_yaml(text, str(path))
    mjcf = _rel(path.parent / str(raw.get("mjcf", "scene.xml")), out_dir)
    for key, value in (("mjcf", mjcf), ("robot", "robot.yaml")):
        line = f"{key}: {value}"
        text, n = re.subn(rf"^{key}:.*$", line, text, count=1, flags=re.MULTILINE)
        if not n:
            text = text.rstrip("\n") + f"\n{line}\n"
    return text
