"""The keyboard operator: a person drives the POI target from MuJoCo's passive viewer.

Key presses arrive one per press on the viewer's thread; they are queued and applied in
the simulation loop, which keeps real time. The viewer is closed explicitly at the end
(a passive viewer left open can hang the process on exit).

Keys (shown in the viewer's title and ``smc record --help``):

=============  ===========================================
arrows         move the target in x (up/down) and y (left/right), 1 cm per press
Page Up/Down   move the target up / down, 1 cm per press
Q / E          yaw +/- 5 degrees
G              toggle the gripper (open <-> closed)
M              saliency mark (the "this moment matters" button)
Enter          finish: keep the log
X              discard: delete the log
=============  ===========================================
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable

import numpy as np

from smccli.errors import SmcError
from smccli.record.operators import OperatorOutput
from smccli.world.sensors import PoiCommand, SaliencyMark
from smccli.world.sim import Sim

# GLFW key codes (the viewer passes them to key_callback).
KEY_RIGHT, KEY_LEFT, KEY_DOWN, KEY_UP = 262, 263, 264, 265
KEY_PAGE_UP, KEY_PAGE_DOWN, KEY_ENTER = 266, 267, 257
HELP = (
    "keyboard operator ready: arrows x/y, PgUp/PgDn z, Q/E yaw, G gripper, M mark, "
    "Enter finish, X discard"
)
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
}


class KeyboardOperator:
    """Reads queued key presses each control tick and turns them into POI commands."""

    def __init__(
        self,
        sim: Sim,
        *,
        realtime: bool = True,
        on_ready: Callable[[str], None] | None = None,
    ) -> None:
        import mujoco.viewer

        self.sim = sim
        self.keys: queue.Queue[int] = queue.Queue()
        self.target = sim.poi().copy()
        self.gripper = 1.0
        self.realtime = realtime
        self._on_ready = on_ready
        self.discarded = False
        """True once the operator pressed X: the recording is thrown away."""
        self._t0_wall = time.perf_counter()
        self._t0_sim = sim.t
        try:
            self.viewer = mujoco.viewer.launch_passive(
                sim.model,
                sim.data,
                key_callback=self.keys.put,
                show_left_ui=False,
                show_right_ui=False,
            )
        except Exception as exc:  # no display, no GL context
            raise SmcError(
                f"keyboard operator: cannot open the MuJoCo viewer ({exc}); it "
                "needs a display (set DISPLAY, or run under xvfb-run with "
                "MUJOCO_GL=glfw)"
            ) from None
        # MuJoCo's viewer shows geom groups 0-2; the robot's own geoms sit in their group.
        with self.viewer.lock():
            self.viewer.opt.geomgroup[sim.robot.geom_group] = 1

    def tick(self) -> OperatorOutput:
        """Apply the presses queued since the last tick; keep real time; sync the viewer."""
        marks: list[SaliencyMark] = []
        done = discard = False
        while True:
            try:
                key = self.keys.get_nowait()
            except queue.Empty:
                break
            kind, delta = BINDINGS.get(key, (None, None))
            if kind == "move" and delta is not None:
                self.target = self.target + delta
            elif kind == "gripper":
                self.gripper = 0.0 if self.gripper > 0.5 else 1.0
            elif kind == "mark":
                marks.append(SaliencyMark(t=self.sim.t, source="operator", label="keyboard"))
            elif kind == "finish":
                done = True
            elif kind == "discard":
                done = discard = True
        if not self.viewer.is_running():
            done = True
        if self.realtime:
            ahead = (self.sim.t - self._t0_sim) - (time.perf_counter() - self._t0_wall)
            if ahead > 0:
                time.sleep(ahead)
        self.viewer.sync()
        if self._on_ready is not None:
            # The viewer has drawn and is reading keys: tell the person (and tests).
            self._on_ready(HELP)
            self._on_ready = None
        cmd = PoiCommand(t=self.sim.t, target=self.target.copy(), gripper=self.gripper)
        self.discarded = self.discarded or discard
        return OperatorOutput(command=cmd, marks=tuple(marks), done=done)

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
