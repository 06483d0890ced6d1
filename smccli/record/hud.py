"""What the keyboard operator's viewer shows: the commanded target, the POI and a HUD.

The paper's simulation drove the end effector with an interactive marker; here the
commanded target is the mocap body :data:`~smccli.world.sim.MARKER_BODY` (magenta sphere).
A person double-clicks it and drags it with Ctrl + right drag (Ctrl + left drag turns it:
only the yaw about the vertical is kept, the gripper points down); the keys still step it.
Two bars beside the sphere show the gripper as commanded (apart: open; together: closed,
orange), a cyan sphere the POI as measured and a line joins the two, so a person sees how
far the arm lags. For a mobile base the target is the base's pose on the floor.

The text overlay (top left) shows the session's episode, the mode, simulated time, the
gripper, the marks so far, the target and the POI; the keys of the mode are listed bottom
left. Everything here is drawn through the passive viewer's user scene and texts: nothing
is added to the physics, and the sensor camera never sees it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from smccli.world.geometry import quat_matrix, yaw_of, yaw_quat
from smccli.world.sim import MARKER_RADIUS, Sim

TARGET_RGBA = np.array([1.0, 0.1, 0.9, 0.7], dtype=np.float32)
"""The target (the mocap sphere's colour, for the drawing without a mocap body)."""
OPEN_RGBA = np.array([0.2, 0.9, 0.3, 0.9], dtype=np.float32)
"""The gripper bars while the command is open."""
CLOSED_RGBA = np.array([1.0, 0.55, 0.0, 0.9], dtype=np.float32)
"""The gripper bars while the command is closed."""
POI_RGBA = np.array([0.0, 0.85, 1.0, 0.9], dtype=np.float32)
"""The POI as measured."""
BAR = np.array([0.006, 0.004, 0.02])
"""Half sizes of a gripper bar [m] (x along the gripper's yaw, y across, z up)."""
BAR_GAP = {True: 0.045, False: 0.012}
"""Half distance between the bars [m]: open / closed (a sketch, not the robot's fingers)."""

KEYS = {
    "arm": (
        "arrows\nPgUp / PgDn\nQ / E\nG\nM\nCtrl+right drag\nCtrl+left drag",
        "target x / y, 1 cm\ntarget z, 1 cm\nyaw +/- 5 deg\ngripper\nmark (salient moment)"
        "\nmove the marker (double-click it first)\nturn the marker",
    ),
    "base": (
        "hold arrows\nhold Q / E\nShift\nM",
        "drive forward / back, strafe\nturn\nhalf speed\nmark (salient moment)",
    ),
}
"""Keys of each mode: (keys, what they do), two columns."""
SESSION_KEYS = (
    "Enter\nX\nEsc",
    "keep the demonstration\ndiscard it (record it again)\nkeep it and end the session",
)
"""Keys that end an episode."""
TAB_KEY = ("Tab", "switch base / arm")


@dataclass(frozen=True, slots=True)
class HudState:
    """What the HUD shows on one tick."""

    mode: str
    """``arm`` or ``base`` (what the keys move)."""
    t: float
    """Simulation time [s]."""
    gripper_open: bool
    """The commanded gripper."""
    marks: int
    """Saliency marks so far in this episode."""
    target: np.ndarray
    """Commanded target ``[x, y, z, yaw]`` in the command's frame [m, rad]."""
    poi: np.ndarray
    """Measured POI ``[x, y, z, yaw]`` in the same frame [m, rad]."""
    episode: tuple[int, int] | None = None
    """(this episode, episodes in the session), 1-based; None outside a session."""
    tab: bool = False
    """Tab switches modes (a mobile manipulator)."""
    last_task: str | None = None
    """What the recorder found at the end of the session's previous demonstration (its
    task achieved or failed, and why); None: no previous one, or a scene without a task."""


def to_world(sim: Sim, target: np.ndarray) -> tuple[np.ndarray, float]:
    """A target ``[x, y, z, yaw]`` in the command's frame as a world position (3,) [m] and
    yaw [rad]."""
    R, p = sim.poi_frame()
    yaw_frame = yaw_of(R)
    return p + R @ np.asarray(target[:3], dtype=float), float(target[3]) + yaw_frame


def from_world(sim: Sim, pos: np.ndarray, quat: np.ndarray, keep_z: float) -> np.ndarray:
    """A dragged marker's world pose (position (3,), quaternion ``[w, x, y, z]``) as a target
    ``[x, y, z, yaw]`` in the command's frame; only the yaw of the marker's x axis counts
    (a top-down gripper). ``keep_z``: the z to keep for a target that lives on the floor
    (a mobile base's)."""
    R, p = sim.poi_frame()
    local = R.T @ (np.asarray(pos, dtype=float) - p)
    axis = quat_matrix(quat)[:, 0]
    axis_local = R.T @ axis
    yaw = math.atan2(axis_local[1], axis_local[0])
    z_out = keep_z if sim.robot.base is not None and not sim.robot.arm_joints else local[2]
    return np.array([local[0], local[1], z_out, yaw])


def place_marker(sim: Sim, target: np.ndarray) -> None:
    """Put the marker body on ``target`` (the command's frame), yaw only."""
    if sim.marker_id < 0:
        return
    pos, yaw = to_world(sim, target)
    mocap = sim.model.body_mocapid[sim.marker_id]
    sim.data.mocap_pos[mocap] = pos
    sim.data.mocap_quat[mocap] = yaw_quat(yaw)


def marker_pose(sim: Sim) -> tuple[np.ndarray, np.ndarray] | None:
    """The marker body's world pose (position, quaternion ``[w, x, y, z]``), or None."""
    if sim.marker_id < 0:
        return None
    mocap = sim.model.body_mocapid[sim.marker_id]
    return sim.data.mocap_pos[mocap].copy(), sim.data.mocap_quat[mocap].copy()


def _geom(scn: Any, kind: int, size: Any, pos: Any, mat: Any, rgba: Any) -> None:
    if scn.ngeom >= scn.maxgeom:
        return
    mujoco.mjv_initGeom(
        scn.geoms[scn.ngeom],
        kind,
        np.asarray(size, dtype=float),
        np.asarray(pos, dtype=float),
        np.asarray(mat, dtype=float).ravel(),
        np.asarray(rgba, dtype=np.float32),
    )
    scn.ngeom += 1


def draw_scene(scn: Any, sim: Sim, state: HudState) -> None:
    """Draw the target (without a mocap body: a sphere), the gripper bars, the POI and the
    line between them into the viewer's user scene ``scn`` (cleared first)."""
    scn.ngeom = 0
    pos, yaw = to_world(sim, state.target)
    rot = quat_matrix(yaw_quat(yaw))
    if sim.marker_id < 0:
        _geom(scn, mujoco.mjtGeom.mjGEOM_SPHERE, [MARKER_RADIUS, 0, 0], pos, np.eye(3), TARGET_RGBA)
    rgba = OPEN_RGBA if state.gripper_open else CLOSED_RGBA
    gap = BAR_GAP[state.gripper_open]
    for side in (-1.0, 1.0):
        centre = pos + rot @ np.array([0.0, side * gap, -MARKER_RADIUS - BAR[2]])
        _geom(scn, mujoco.mjtGeom.mjGEOM_BOX, BAR, centre, rot, rgba)
    poi, _ = to_world(sim, state.poi)
    _geom(scn, mujoco.mjtGeom.mjGEOM_SPHERE, [0.012, 0, 0], poi, np.eye(3), POI_RGBA)
    if scn.ngeom < scn.maxgeom and np.linalg.norm(poi - pos) > 1e-4:
        g = scn.geoms[scn.ngeom]
        mujoco.mjv_initGeom(
            g,
            mujoco.mjtGeom.mjGEOM_LINE,
            np.zeros(3),
            np.zeros(3),
            np.eye(3).ravel(),
            POI_RGBA,
        )
        mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_LINE, 3.0, poi, pos)
        scn.ngeom += 1


def _pose(p: np.ndarray) -> str:
    return f"x {p[0]:+.3f}  y {p[1]:+.3f}  z {p[2]:+.3f}  yaw {math.degrees(p[3]):+4.0f}"


def texts(state: HudState) -> list[tuple[int, int, str, str]]:
    """The overlays: status top left, the mode's keys bottom left."""
    labels, values = [], []
    if state.episode is not None:
        labels.append("episode")
        values.append(f"{state.episode[0]} / {state.episode[1]}")
    labels += ["mode", "time", "gripper", "marks", "target", "POI"]
    values += [
        state.mode.upper(),
        f"{state.t:6.2f} s",
        "open" if state.gripper_open else "CLOSED",
        str(state.marks),
        _pose(state.target),
        _pose(state.poi),
    ]
    if state.last_task is not None:
        labels.append("last demo")
        values.append(state.last_task)
    keys, does = KEYS[state.mode]
    keys, does = f"{keys}\n{SESSION_KEYS[0]}", f"{does}\n{SESSION_KEYS[1]}"
    if state.tab:
        keys, does = f"{keys}\n{TAB_KEY[0]}", f"{does}\n{TAB_KEY[1]}"
    font = mujoco.mjtFontScale.mjFONTSCALE_150
    return [
        (font, mujoco.mjtGridPos.mjGRID_TOPLEFT, "\n".join(labels), "\n".join(values)),
        (font, mujoco.mjtGridPos.mjGRID_BOTTOMLEFT, keys, does),
    ]
