"""The keyboard operator: a person drives the robot from MuJoCo's passive viewer.

The robot file decides the mode. An arm moves its POI target one step per key press; a
mobile base (``robot.base`` set, no arm) is driven by holding keys, like a game or a
TidyBot / ManiSkill teleop; a mobile manipulator does both, Tab switching between its base
and its arm (the hand's target in the base's frame), the mode shown in the viewer. Key
presses arrive on the viewer's thread; they are queued and
applied in the simulation loop, which keeps real time. The viewer is closed explicitly at
the end (a passive viewer left open can hang the process on exit).

Keys (the ready message lists them):

Arm, one step per press:

=============  ===========================================
arrows         move the target in x (up/down) and y (left/right), 1 cm per press
Page Up/Down   move the target up / down, 1 cm per press
Q / E          yaw +/- 5 degrees
G              toggle the gripper (open <-> closed)
M              saliency mark (the "this moment matters" button)
Enter          finish: keep the log
X              discard: delete the log
=============  ===========================================

Mobile base, hold to drive (body frame: forward is where the base faces):

=============  ===========================================
Up / Down      drive forward / back, 0.4 m/s
Left / Right   strafe left / right, 0.4 m/s (with Up/Down: diagonal, same speed)
Q / E          turn left / right (counter-clockwise / clockwise), 0.8 rad/s
Shift          held with the above: half speed (0.2 m/s, 0.4 rad/s), for fine positioning
M              saliency mark
Enter          finish: keep the log
X              discard: delete the log
=============  ===========================================

Holding a key. MuJoCo 4.0's passive viewer calls ``key_callback`` with the key code for a
press only: its GLFW adapter drops GLFW's repeat and release events, so the callback cannot
tell a held key from a tap. The base mode reads GLFW's own key state of the viewer's window
instead (``glfwGetKey``, the same GLFW library the viewer runs on) every tick. The window is
GLFW's current context on the viewer's thread, taken in the first key callback; it is read
under the viewer's lock, which that thread holds while it polls events, so the window is
alive and its key table is not being written. A key counts as down for a tick if GLFW says
so or if it was pressed since the last tick (a tap shorter than a tick still moves one
tick). GLFW releases every key when the window loses focus, so a key never sticks down. If
the window cannot be had (another platform or MuJoCo version), each press drives for
:data:`HOLD_S` instead.

Driving. The keys down give a body-frame twist; each tick it is rotated by the measured
heading and integrated into the world pose target ``[x, y, 0, yaw]`` sent as the POI
command. The base's position servos follow with a lag that grows with speed; on release the
target stays put and the base settles onto it, which is how far it coasts (about 1 s from
full speed). Shift halves the speeds rather than doubling them: the base saturates at 1 m/s
and 1.5 rad/s (force caps against joint damping, ``robots/base/robot.xml``), so twice 0.8
rad/s could not be followed. The target may lead the measured pose by at most
:data:`MAX_LEAD_M` and :data:`MAX_LEAD_RAD`, so a base held against a wall (its servos are
force limited) does not wind up a target it would later run to; once nothing is held and the
base has stalled short of its target (blocked), the target drops back to the measured pose,
so it stops pushing. The viewer's camera tracks the base.

The viewer's own shortcuts. MuJoCo's viewer takes every letter key for itself (render and
visualisation toggles), even with its panels hidden, which is why the base drives with the
arrows and not W/A/S/D: W toggles wireframe, S shadows, D hides static bodies (the walls).
The visualisation flags toggled by the letters this operator uses (Q, E, X, M; for a base
also A and D) are put back every tick; W and S (and the arm's G, fog) toggle render flags,
which the passive viewer's handle does not reach.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from smccli.errors import SmcError
from smccli.record.hud import (
    HudState,
    draw_scene,
    from_world,
    marker_pose,
    place_marker,
    texts,
)
from smccli.record.operators import OperatorOutput
from smccli.world.geometry import wrap
from smccli.world.robot import robot_geoms
from smccli.world.sensors import PoiCommand, SaliencyMark
from smccli.world.sim import HIDDEN_GROUP, Sim

# GLFW key codes (the viewer passes them to key_callback).
KEY_RIGHT, KEY_LEFT, KEY_DOWN, KEY_UP = 262, 263, 264, 265
KEY_PAGE_UP, KEY_PAGE_DOWN, KEY_ENTER = 266, 267, 257
KEY_LEFT_SHIFT, KEY_RIGHT_SHIFT = 340, 344
KEY_ESCAPE = 256
HELP = (
    "keyboard operator ready: arrows x/y, PgUp/PgDn z, Q/E yaw, G gripper, M mark, "
    "Enter finish, X discard, Esc finish and end the session; double-click the magenta "
    "marker, then Ctrl+right drag moves it (Ctrl+left drag turns it)"
)
BASE_HELP = (
    "keyboard operator ready (mobile base, hold keys to drive): Up/Down forward/back, "
    "Left/Right strafe, Q/E turn, Shift half speed, M mark, Enter finish, X discard, "
    "Esc finish and end the session"
)
MM_HELP = (
    "keyboard operator ready (mobile manipulator, Tab switches base/arm, shown top left): "
    "base: hold Up/Down/Left/Right/Q/E to drive, Shift half speed; arm (in the base's "
    "frame): arrows x/y, PgUp/PgDn z, Q/E yaw, G gripper, or drag the magenta marker; "
    "M mark, Enter finish, X discard, Esc finish and end the session"
)
KEY_TAB = 258
"""Switches a mobile manipulator between driving its base and moving its hand."""
STEP_M = 0.01
STEP_YAW = math.radians(5)
BINDINGS = {
    KEY_UP: ("move", np.array([STEP_M, 0, 0, 0])),
    KEY_DOWN: ("move", np.array([-STEP_M, 0, 0, 0])),
    KEY_LEFT: ("move", np.array([0, STEP_M, 0, 0])),
    KEY_RIGHT: ("move", np.array([0, -STEP_M, 0, 0])),
    KEY_PAGE_UP: ("move", np.array([0, 0, STEP_M, 0])),
    KEY_PAGE_DOWN: ("move", np.array([0, 0, -STEP_M, 0])),
    ord("Q"): ("move", np.array([0, 0, 0, STEP_YAW])),
    ord("E"): ("move", np.array([0, 0, 0, -STEP_YAW])),
    ord("G"): ("gripper", None),
    ord("M"): ("mark", None),
    KEY_ENTER: ("finish", None),
    ord("X"): ("discard", None),
    KEY_ESCAPE: ("stop", None),
}
EVENTS = {ord("M"): "mark", KEY_ENTER: "finish", ord("X"): "discard", KEY_ESCAPE: "stop"}
"""Keys the base mode acts on per press; the drive keys below act while held."""

BASE_SPEED = 0.4
"""Nominal translation speed of the base [m/s]."""
BASE_TURN = 0.8
"""Nominal turn rate of the base [rad/s]."""
SLOW = 0.5
"""Speed factor while Shift is held."""
MAX_LEAD_M = 0.3
"""How far the position target may lead the measured base position [m]."""
MAX_LEAD_RAD = 0.5
"""How far the yaw target may lead the measured heading [rad]."""
STALL = (0.01, 0.02)
"""Base speed [m/s] and turn rate [rad/s] under which a base with nothing held and its
target further than :data:`STALL_LEAD` away counts as blocked."""
STALL_LEAD = (0.02, 0.05)
"""Lead [m], [rad] beyond which a base at rest counts as blocked (moving freely, its
over-damped servos never rest that far from their target: speed ≈ 4.5/s × lead, turn rate
≈ 10/s × lead)."""
HOLD_S = 0.3
"""Without GLFW's key state (see the module docstring): how long a press drives [s]."""
DRIVE = {
    # key: (forward, left, counter-clockwise) in units of the nominal speeds
    KEY_UP: (1, 0, 0),
    KEY_DOWN: (-1, 0, 0),
    KEY_LEFT: (0, 1, 0),
    KEY_RIGHT: (0, -1, 0),
    ord("Q"): (0, 0, 1),
    ord("E"): (0, 0, -1),
}
SHIFT = (KEY_LEFT_SHIFT, KEY_RIGHT_SHIFT)
HELD = (*DRIVE, *SHIFT)
"""Keys whose state (down or up) the base mode reads each tick."""
HUD_PERIOD = 0.1
"""The overlay's numbers are redrawn at most this often [s of wall time]: the viewer's
``set_texts`` waits for its render thread to draw a frame (20 ms a call under Xvfb's
software GL, measured), and called every control period it held a session at a third of
real time. A change of mode, gripper, marks or episode is shown at once."""


def twist(held: Iterable[int]) -> np.ndarray:
    """Body-frame twist ``[vx, vy, wz]`` [m/s, m/s, rad/s] for the keys held.

    Opposite keys cancel; a diagonal goes at the nominal speed, not √2 times it.
    """
    held = set(held)
    d = np.zeros(3)
    for k in held & DRIVE.keys():
        d += DRIVE[k]
    xy = d[:2]
    norm = float(np.hypot(*xy))
    v = np.zeros(3)
    if norm > 0:
        v[:2] = xy / norm * BASE_SPEED
    v[2] = np.sign(d[2]) * BASE_TURN
    if held & set(SHIFT):
        v *= SLOW
    return v


class BaseDriver:
    """Integrates the body-frame twist of the keys held into a lead-clamped pose target.

    Pure (no viewer, no simulator): :meth:`update` takes the keys held and the measured base
    pose each control tick and returns the target ``[x, y, 0, yaw]`` to send.
    """

    def __init__(self, pose: np.ndarray, dt: float) -> None:
        self.target = np.array([pose[0], pose[1], 0.0, pose[3]], dtype=float)
        """World pose target ``[x, y, 0, yaw]``; yaw continuous (never wrapped)."""
        self.dt = dt
        self._last: np.ndarray | None = None

    def update(self, held: Iterable[int], pose: np.ndarray) -> np.ndarray:
        """Advance the target one tick with the keys ``held``; ``pose`` is the measured
        ``[x, y, z, yaw]``."""
        v = twist(held)
        xy, yaw = np.array(pose[:2], dtype=float), float(pose[3])
        c, s = math.cos(yaw), math.sin(yaw)
        tgt = self.target
        tgt[:2] += np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]]) * self.dt
        tgt[3] += v[2] * self.dt
        # Lead: how far the target is ahead of the base (yaw: the nearest turn).
        lead = tgt[:2] - xy
        dist = float(np.hypot(*lead))
        lead_yaw = wrap(float(tgt[3]) - yaw)
        if self._last is not None:
            speed = float(np.hypot(*(xy - self._last[:2]))) / self.dt
            rate = abs(wrap(yaw - float(self._last[2]))) / self.dt
            # Nothing commanded, the base at rest short of its target: it is blocked. Let go.
            if not v[:2].any() and speed < STALL[0] and dist > STALL_LEAD[0]:
                lead[:] = 0.0
                dist = 0.0
            if v[2] == 0 and rate < STALL[1] and abs(lead_yaw) > STALL_LEAD[1]:
                lead_yaw = 0.0
        self._last = np.array([*xy, yaw])
        if dist > MAX_LEAD_M:
            lead *= MAX_LEAD_M / dist
        tgt[:2] = xy + lead
        # Shift the yaw target by the excess only, so it stays continuous.
        kept = float(np.clip(lead_yaw, -MAX_LEAD_RAD, MAX_LEAD_RAD))
        tgt[3] -= wrap(float(tgt[3]) - yaw) - kept
        return tgt.copy()


def key_action(key: int, base: bool) -> tuple[str | None, np.ndarray | None]:
    """What a press does: ``(kind, delta)``, kind one of move, gripper, mark, finish,
    discard, stop (finish and end the session) or None. A base's drive keys act while
    held (:func:`twist`), not per press."""
    if base:
        return EVENTS.get(key), None
    return BINDINGS.get(key, (None, None))


def held_from_presses(pressed_at: dict[int, float], t: float) -> set[int]:
    """Without GLFW's key state: the keys pressed less than :data:`HOLD_S` before ``t``."""
    return {k for k, t0 in pressed_at.items() if t - t0 < HOLD_S}


def _open_viewer(sim: Sim, on_key: Callable[[int], None]) -> Any:
    """MuJoCo's passive viewer on ``sim``, its panels hidden, ``on_key`` its key callback.
    Raises SmcError (naming the fix) when there is no display."""
    import mujoco.viewer

    try:
        return mujoco.viewer.launch_passive(
            sim.model,
            sim.data,
            key_callback=on_key,
            show_left_ui=False,
            show_right_ui=False,
        )
    except Exception as exc:  # no display, no GL context
        raise SmcError(
            f"keyboard operator: cannot open the MuJoCo viewer ({exc}); it "
            "needs a display (set DISPLAY, or run under xvfb-run with "
            "MUJOCO_GL=glfw)"
        ) from None


class KeyboardOperator:
    """Reads queued key presses each control tick and turns them into POI commands."""

    def __init__(
        self,
        sim: Sim,
        *,
        realtime: bool = True,
        on_ready: Callable[[str], None] | None = None,
    ) -> None:
        self.sim = sim
        self.keys: queue.Queue[int] = queue.Queue()
        self.target = sim.poi().copy()
        self.gripper = 1.0
        self.realtime = realtime
        self._on_ready = on_ready
        self.discarded = False
        """True once the operator pressed X: the recording is thrown away."""
        self.stopped = False
        """True once the operator pressed Esc: keep this recording, record no more."""
        self.marks = 0
        """Saliency marks so far in this episode (shown in the HUD)."""
        self.episode: tuple[int, int] | None = None
        """(this episode, episodes in the session), 1-based, shown in the HUD."""
        self.last_task: str | None = None
        """The HUD's verdict on the previous demonstration (set by the session)."""
        self._placed: tuple[np.ndarray, np.ndarray] | None = None  # the marker's last pose
        self._hud: tuple[object, float] | None = None  # what the overlay shows, since when
        self.mobile_manipulator = sim.mobile_manipulator
        """Base and arm: Tab switches what the keys move (:attr:`mode`)."""
        self.mode = "base" if self.mobile_manipulator else None
        """A mobile manipulator's mode: ``base`` (hold keys to drive) or ``arm`` (a step per
        press, the hand's target in the base's frame); shown in the viewer."""
        self.base = (
            sim.robot.base is not None and not sim.robot.arm_joints
        ) or self.mobile_manipulator
        """The keys drive a base while held (a mobile base; a mobile manipulator in mode
        ``base``); else an arm, a step per press."""
        self.base_target = self._base_pose() if self.mobile_manipulator else None
        """A mobile manipulator's base target ``[x, y, 0, yaw]`` (odometry's frame)."""
        start = self.base_target if self.base_target is not None else self.target
        self.driver = BaseDriver(start, sim.control_period) if self.base else None
        self._window: Any = None  # GLFW window of the viewer (first key callback)
        self._pressed_at: dict[int, float] = {}
        self._t0_wall: float | None = None  # real time starts at the first tick
        self._t0_sim = sim.t
        self.viewer = _open_viewer(sim, self._on_key)
        with self.viewer.lock():
            self._flags = self._set_up_view()

    def _set_up_view(self) -> dict[int, int]:
        """Show the robot's and the hidden geom groups; for a base, track it with the camera.
        Returns the visualisation flags the operator's letters toggle, as they are now
        (:meth:`tick` puts them back). Called under the viewer's lock."""
        import mujoco

        sim, opt = self.sim, self.viewer.opt
        # MuJoCo's viewer shows geom groups 0-2; the robot's may sit in another: show the
        # groups of its visual geoms (those that collide with nothing), or all of its own.
        m = sim.model
        own = robot_geoms(sim.robot, m)
        visual = [g for g in own if m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0]
        for group in {int(m.geom_group[g]) for g in (visual or own)}:
            opt.geomgroup[group] = 1
        opt.geomgroup[HIDDEN_GROUP] = 1
        # Visualisation flags the viewer toggles on letters this operator uses (and, for
        # a base, on A and D: W/A/S/D come to hand, and D would hide the walls).
        keys = (*DRIVE, *EVENTS, ord("A"), ord("D"), *BINDINGS) if self.base else BINDINGS
        letters = {chr(k) for k in keys if ord("A") <= k <= ord("Z")}
        flags = {
            i: int(opt.flags[i])
            for i, (_, _, key) in enumerate(mujoco.mjVISSTRING)
            if key in letters
        }
        if self.base:
            pose = self._base_pose() if self.mobile_manipulator else sim.poi()
            cam = self.viewer.cam
            cam.type = mujoco.mjtCamera.mjCAMERA_TRACKING
            cam.trackbodyid = (
                int(sim.model.body_rootid[sim.model.site_bodyid[sim.poi_id]])
                if self.mobile_manipulator
                else int(sim.model.site_bodyid[sim.poi_id])
            )
            # From above and behind: over the walls (2 m high), facing the base's +x.
            cam.distance, cam.elevation, cam.azimuth = 4.0, -70.0, float(np.degrees(pose[3]))
        return flags

    def _base_pose(self) -> np.ndarray:
        """A mobile manipulator's base pose ``[x, y, 0, yaw]`` from odometry."""
        x, y, yaw = self.sim.base_odometry()
        return np.array([x, y, 0.0, yaw])

    @property
    def driving(self) -> bool:
        """The keys drive the base this tick (held keys), else they step the arm."""
        return self.base and self.mode != "arm"

    def _show(self) -> None:
        """Marker, user-scene drawings and text overlays for this tick (record/hud.py)."""
        state = HudState(
            mode="base" if self.driving else "arm",
            t=self.sim.t,
            gripper_open=self.gripper > 0.5,
            marks=self.marks,
            target=self.target,
            poi=self.sim.poi(),
            episode=self.episode,
            tab=self.mobile_manipulator,
            last_task=self.last_task,
        )
        place_marker(self.sim, self.target)
        self._placed = marker_pose(self.sim)
        with self.viewer.lock():
            if self.viewer.user_scn is not None:
                draw_scene(self.viewer.user_scn, self.sim, state)
        # The discrete fields at once, the numbers (time, poses) every HUD_PERIOD.
        fields = (state.mode, state.gripper_open, state.marks, state.episode, state.last_task)
        now = time.perf_counter()
        if self._hud is None or self._hud[0] != fields or now - self._hud[1] >= HUD_PERIOD:
            self.viewer.set_texts(texts(state))
            self._hud = (fields, now)

    def _dragged(self) -> None:
        """Take the marker's pose as the target if the person moved it since the last tick
        (the viewer writes a dragged mocap body's pose on sync). Compared with the pose it
        was given, not recomputed: a mobile manipulator's base moves the frame between
        ticks."""
        pose = marker_pose(self.sim)
        if pose is None or self._placed is None or self.driving:
            return
        if max(np.abs(a - b).max() for a, b in zip(pose, self._placed, strict=True)) > 1e-9:
            self.target = from_world(self.sim, pose[0], pose[1], keep_z=float(self.target[2]))

    def reset(self, episode: tuple[int, int] | None = None) -> None:
        """Start a new episode on the simulation as it now is (``Sim.reset`` done)."""
        while not self.keys.empty():
            self.keys.get_nowait()
        self.target = self.sim.poi().copy()
        self.gripper = 1.0
        self.discarded = self.stopped = False
        self.marks = 0
        self.episode = episode
        self.mode = "base" if self.mobile_manipulator else None
        self.base_target = self._base_pose() if self.mobile_manipulator else None
        if self.driver is not None:
            start = self.base_target if self.base_target is not None else self.target
            self.driver = BaseDriver(start, self.sim.control_period)
        self._pressed_at.clear()
        self._t0_wall = None
        self._placed = None

    def _on_key(self, key: int) -> None:
        """The viewer's key callback (its thread): queue the press; note the window."""
        if self.base and self._window is None:
            try:
                import glfw

                self._window = glfw.get_current_context()
            except Exception:  # no key state: presses hold for HOLD_S
                self._window = None
        self.keys.put(key)

    def _held(self, pressed: set[int]) -> set[int]:
        """Base keys down this tick (see the module docstring)."""
        t = self.sim.t
        for k in pressed:
            self._pressed_at[k] = t
        if self._window is not None:
            try:
                import glfw

                with self.viewer.lock():
                    if self.viewer.is_running():
                        return pressed | {
                            k for k in HELD if glfw.get_key(self._window, k) == glfw.PRESS
                        }
            except Exception:  # fall back on presses
                self._window = None
        return pressed | held_from_presses(self._pressed_at, t)

    def tick(self) -> OperatorOutput:
        """Apply the presses queued since the last tick; keep real time; sync the viewer."""
        marks: list[SaliencyMark] = []
        done = discard = False
        pressed: set[int] = set()
        self._dragged()
        while True:
            try:
                key = self.keys.get_nowait()
            except queue.Empty:
                break
            if key == KEY_TAB and self.mobile_manipulator:
                self.mode = "arm" if self.mode == "base" else "base"
                continue
            kind, delta = key_action(key, self.driving)
            if self.driving and key in HELD:
                pressed.add(key)
            if kind == "move" and delta is not None:
                self.target = self.target + delta
            elif kind == "gripper":
                self.gripper = 0.0 if self.gripper > 0.5 else 1.0
            elif kind == "mark":
                marks.append(SaliencyMark(t=self.sim.t, source="operator", label="keyboard"))
                self.marks += 1
            elif kind == "finish":
                done = True
            elif kind == "discard":
                done = discard = True
            elif kind == "stop":
                done = self.stopped = True
        if self.driver is not None and self.mobile_manipulator:
            held = self._held(pressed) if self.driving else set()
            self.base_target = self.driver.update(held, self._base_pose())
        elif self.driver is not None:
            self.target = self.driver.update(self._held(pressed), self.sim.poi())
        if not self.viewer.is_running():
            done = True
        if self._t0_wall is None:
            # Not at construction: opening the viewer and the recorder's first camera frame
            # take seconds, which the simulation would then race through to catch up.
            self._t0_wall, self._t0_sim = time.perf_counter(), self.sim.t
        if self.realtime:
            ahead = (self.sim.t - self._t0_sim) - (time.perf_counter() - self._t0_wall)
            if ahead > 0:
                time.sleep(ahead)
        with self.viewer.lock():
            for i, v in self._flags.items():
                self.viewer.opt.flags[i] = v
        self._show()
        self.viewer.sync()
        # Only the marker may be dragged: a Ctrl-drag on any other body pushes it, which no
        # command in the log would explain (``smc replay --verify`` would flag the log).
        self.sim.clear_pushes()
        if self._on_ready is not None:
            # The viewer has drawn and is reading keys: tell the person (and tests).
            self._on_ready(MM_HELP if self.mobile_manipulator else BASE_HELP if self.base else HELP)
            self._on_ready = None
        base = None if self.base_target is None else self.base_target[[0, 1, 3]].copy()
        cmd = PoiCommand(t=self.sim.t, target=self.target.copy(), gripper=self.gripper, base=base)
        self.discarded = self.discarded or discard
        return OperatorOutput(command=cmd, marks=tuple(marks), done=done)

    @property
    def window_open(self) -> bool:
        """The viewer's window is still open (the person has not closed it)."""
        return bool(self.viewer.is_running())

    def close(self) -> None:
        """Close the viewer window and wait for its thread to finish.

        The viewer registers ``glfw.terminate`` to run at exit; if its render thread is
        still tearing down when that runs, the process segfaults. Python names a thread
        after its target, which is how the (unexposed) viewer thread is found.
        """
        self.viewer.close()
        for thread in threading.enumerate():
            if "_launch_internal" in thread.name:
                thread.join(timeout=10.0)
