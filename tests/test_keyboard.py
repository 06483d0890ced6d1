"""The keyboard operator, driven for real: MuJoCo's viewer under Xvfb, keys sent by xdotool.

The mobile base's driving (speeds, body frame, release, lead clamp) is also checked without
a viewer, through :class:`BaseDriver` on the simulator, tick by tick in simulated time.
``smc replay --teach keyboard`` (an operator continues where the tree stops) is driven the
same way.
"""

from __future__ import annotations

import json
import math
import os
import queue
import re
import shutil
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import SAMPLE_LOGS

from smccli.execute.episode import layout_for
from smccli.learn.compile import compile_logs
from smccli.learn.tree import ROOT, digest, load_tree
from smccli.logs import read_log
from smccli.record.keyboard import (
    HOLD_S,
    KEY_DOWN,
    KEY_ENTER,
    KEY_LEFT,
    KEY_LEFT_SHIFT,
    KEY_PAGE_UP,
    KEY_RIGHT,
    KEY_UP,
    MAX_LEAD_M,
    BaseDriver,
    held_from_presses,
    key_action,
    twist,
)
from smccli.world.scene import load_scene
from smccli.world.sensors import PoiCommand
from smccli.world.sim import Sim

BASE_SCENE = str(Path(__file__).parent / "scenes" / "rooms_drive" / "scene.yaml")
KEY_Q, KEY_E = ord("Q"), ord("E")


@pytest.fixture
def display():
    if not (shutil.which("Xvfb") and shutil.which("xdotool")):
        pytest.fail("Xvfb and xdotool are needed (make setup installs them)")
    # Xvfb picks a free display itself and writes its number to the pipe once it listens:
    # no race with another test process choosing the same number.
    read_fd, write_fd = os.pipe()
    xvfb = subprocess.Popen(
        ["Xvfb", "-displayfd", str(write_fd), "-screen", "0", "1280x1024x24", "-nolisten", "tcp"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        pass_fds=(write_fd,),
    )
    os.close(write_fd)
    with os.fdopen(read_fd) as pipe:
        n = pipe.readline().strip()
    assert n.isdigit(), f"Xvfb did not start (exit code {xvfb.poll()})"
    yield f":{n}"
    xvfb.terminate()
    xvfb.wait(timeout=10)


def _window(env: dict, timeout: float = 60.0) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = subprocess.run(
            ["xdotool", "search", "--onlyvisible", "--name", "MuJoCo"],
            env=env,
            capture_output=True,
            text=True,
        )
        if found.stdout.strip():
            return found.stdout.split()[0]
        time.sleep(0.3)
    raise AssertionError("the MuJoCo viewer window did not appear")


def _focus(env: dict, window: str, timeout: float = 20.0) -> None:
    """Give the viewer the keyboard focus and wait until X reports it has it."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        subprocess.run(["xdotool", "windowfocus", window], env=env, capture_output=True)
        got = subprocess.run(
            ["xdotool", "getwindowfocus"], env=env, capture_output=True, text=True
        ).stdout.strip()
        if got == window:
            time.sleep(1.0)  # the viewer's event loop polls a few times a second
            return
        time.sleep(0.3)
    raise AssertionError("the viewer window never got the keyboard focus")


def _keys(env: dict, window: str, *keys: str, pause: float = 0.15) -> None:
    for k in keys:
        # XTEST to the focused window: real timestamps (synthetic events sent with
        # --window all carry time 0, and GLFW then takes a repeated key for auto-repeat).
        subprocess.run(["xdotool", "key", k], env=env, check=True)
        time.sleep(pause)


STATUS = re.compile(r"recording: sim\s+([\d.]+) s")


class Stderr:
    """The recorder's stderr, read line by line on a thread (so we can wait for a line)."""

    def __init__(self, proc: subprocess.Popen) -> None:
        self.proc = proc
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        self.sim_t = 0.0
        """Simulated time [s] of the recorder's last status line (one per simulated second)."""
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self) -> None:
        for line in self.proc.stderr:
            self.lines.put(line)

    def _next(self, deadline: float) -> str | None:
        try:
            line = self.lines.get(timeout=0.5)
        except queue.Empty:
            assert self.proc.poll() is None, "".join(self.seen)
            assert time.monotonic() < deadline, "".join(self.seen)
            return None
        self._take(line)
        return line

    def _take(self, line: str) -> None:
        self.seen.append(line)
        m = STATUS.search(line)
        if m:
            self.sim_t = float(m.group(1))

    def wait_for(self, text: str, timeout: float = 90.0) -> None:
        deadline = time.monotonic() + timeout
        while True:
            line = self._next(deadline)
            if line is not None and text in line:
                return

    def wait_sim(self, seconds: float, timeout: float = 300.0) -> None:
        """Wait until the recorder has simulated ``seconds`` more: what happens in the scene
        follows simulated time, which a busy machine stretches against the wall clock.

        Counted from the latest status line (lines queued meanwhile are read first, or the
        wait would end early), one per simulated second: from now, between
        ``ceil(seconds) - 1`` and ``ceil(seconds)`` s of simulation pass.
        """
        deadline = time.monotonic() + timeout
        while not self.lines.empty():
            self._take(self.lines.get())
        until = self.sim_t + seconds
        while self.sim_t < until:
            self._next(deadline)

    def rest(self) -> str:
        self.thread.join(timeout=30)
        while not self.lines.empty():
            self.seen.append(self.lines.get())
        return "".join(self.seen)


def _record(tmp_path, display, scene: str = "pick_place", extra: tuple[str, ...] = ()):
    out = tmp_path / "kb.mcap"
    env = {**os.environ, "DISPLAY": display, "MUJOCO_GL": "glfw"}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "smccli.cli",
            "record",
            "--scene",
            scene,
            "--operator",
            "keyboard",
            "-o",
            str(out),
            "--allow-failed",  # a few key presses: they never do the task
            *extra,
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    return out, env, proc


@contextmanager
def _recording(tmp_path, display, scene: str = "pick_place", extra: tuple[str, ...] = ()):
    """A keyboard recording whose viewer is up and has the focus: (out, env, window, stderr)."""
    out, env, proc = _record(tmp_path, display, scene, extra)
    err = Stderr(proc)
    try:
        err.wait_for("keyboard operator ready")
        win = _window(env)
        _focus(env, win)
        yield out, env, win, err
    finally:
        if proc.poll() is None:
            proc.kill()


def _drive(
    tmp_path, display, *presses: tuple[str, ...], scene: str = "pick_place"
) -> tuple[int, str, Path]:
    """Record with the keyboard operator, pressing each group of keys (at least 1.5 s of
    simulation between groups, so the gripper can close); returns (exit code, stderr,
    output path)."""
    with _recording(tmp_path, display, scene) as (out, env, win, err):
        for group in presses[:-1]:
            _keys(env, win, *group)
            err.wait_sim(2.0)  # status lines come once per simulated second
        _keys(env, win, *presses[-1])
        err.proc.wait(timeout=60)
        return err.proc.returncode, err.rest(), out


MAGENTA = ((180, 256), (0, 90), (150, 256))
"""The target marker's colour on screen (and what no camera frame may show): R, G, B ranges."""


def _magenta(rgb: np.ndarray) -> np.ndarray:
    rgb = rgb.astype(int)
    return np.logical_and.reduce(
        [(lo <= rgb[..., i]) & (rgb[..., i] < hi) for i, (lo, hi) in enumerate(MAGENTA)]
    )


def _screenshot(display: str) -> np.ndarray:
    """The whole X screen, (H, W, 3) uint8 (Pillow reads it through XCB)."""
    from PIL import ImageGrab

    return np.asarray(ImageGrab.grab(xdisplay=display).convert("RGB"))


def _window_box(env: dict, window: str) -> tuple[int, int, int, int]:
    """(x, y, width, height) of the window on the screen [px]."""
    out = subprocess.run(
        ["xdotool", "getwindowgeometry", "--shell", window],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    g = dict(line.split("=", 1) for line in out.split())
    return int(g["X"]), int(g["Y"]), int(g["WIDTH"]), int(g["HEIGHT"])


def _drag_marker(env: dict, display: str, dx: int, dy: int) -> None:
    """Find the magenta target marker on screen, select it (double-click) and move it by
    (dx, dy) pixels with Ctrl + right drag, in small steps as a hand would."""
    ys, xs = np.nonzero(_magenta(_screenshot(display)))
    assert len(xs) > 20, "the target marker is not on screen"
    x, y = int(np.median(xs)), int(np.median(ys))

    def xdo(*args: object) -> None:
        subprocess.run(["xdotool", *map(str, args)], env=env, check=True)

    xdo("mousemove", x, y)
    xdo("click", "--repeat", 2, "--delay", 80, 1)
    time.sleep(0.5)
    xdo("keydown", "ctrl")
    xdo("mousedown", 3)
    steps = 30
    for i in range(1, steps + 1):
        xdo("mousemove", x + dx * i // steps, y + dy * i // steps)
        time.sleep(0.03)
    xdo("mouseup", 3)
    xdo("keyup", "ctrl")


@pytest.mark.viewer
def test_a_session_drags_the_marker_steps_keys_and_records_two_episodes(tmp_path, display):
    """``smc record --operator keyboard --episodes 2``. Episode 1: the magenta target
    marker is dragged with the mouse, then Up, G, M and Enter (keep, next). Episode 2: X
    (discard: recorded again), then the keys alone, Enter. Two logs; the HUD's screenshot
    is kept (``SMC_HUD_PNG``: where to copy it, for docs/recording.md)."""
    with _recording(tmp_path, display, extra=("--episodes", "2")) as (out, env, win, err):
        err.wait_sim(1.0)
        _drag_marker(env, display, dx=-90, dy=60)
        err.wait_sim(2.0)  # the arm follows the dragged target
        _keys(env, win, "Up", "g")
        time.sleep(1.0)  # the HUD shows the closed gripper
        x, y, w, h = _window_box(env, win)
        shot = _screenshot(display)[y : y + h, x : x + w]
        from PIL import Image

        Image.fromarray(shot).save(tmp_path / "hud.png")
        if os.environ.get("SMC_HUD_PNG"):
            shutil.copy(tmp_path / "hud.png", os.environ["SMC_HUD_PNG"])
        err.wait_sim(1.0)
        _keys(env, win, "m", "Return")
        err.wait_for("episode 1/2 kept")
        _keys(env, win, "x")
        err.wait_for("episode 2/2 discarded")
        err.wait_sim(1.0)
        _keys(env, win, *("Up",) * 5 + ("Page_Down",) * 3 + ("q", "g"))
        err.wait_sim(2.0)  # the gripper closes
        _keys(env, win, "m", "Return")
        err.proc.wait(timeout=60)
        code, stderr = err.proc.returncode, err.rest()
    assert code == 0, stderr
    assert "episode 2/2 kept" in stderr and "session ended" in stderr
    # Enter's verdict on each demonstration (a few key presses do not do the task): in the
    # session's line, and on the HUD of the next episode (test_hud_shows_the_last_verdict).
    assert "mark(s); task FAILED: " in stderr, stderr
    assert sorted(p.name for p in tmp_path.glob("kb*")) == ["kb-000.mcap", "kb-001.mcap"]
    first_ep, second_ep = read_log(tmp_path / "kb-000.mcap"), read_log(tmp_path / "kb-001.mcap")
    assert first_ep.metadata["episode"] == "1/2" and second_ep.metadata["episode"] == "2/2"

    # Episode 1: the drag moved the target in many small steps, by far more than any key
    # would, yaw untouched (Ctrl + right drag translates); then Up added exactly 1 cm in x.
    target = np.array([c.target for c in first_ep.commands])
    step = np.diff(target, axis=0)
    moves = np.flatnonzero(np.abs(step).max(axis=1) > 1e-9)
    up = [i for i in moves if np.allclose(step[i], [0.01, 0, 0, 0], atol=1e-12)]
    assert len(up) == 1 and up[0] == moves[-1], "one Up press, after the drag"
    dragged = target[up[0]] - target[0]
    assert len(moves) > 5 and np.linalg.norm(dragged[:3]) > 0.05, dragged
    assert np.abs(target[:, 3] - target[0, 3]).max() < 1e-9
    assert first_ep.commands[-1].gripper == 0.0 and len(first_ep.marks) == 1
    # The arm followed the dragged target.
    assert np.linalg.norm(np.asarray(first_ep.poi[-1])[:3] - target[-1, :3]) < 0.01
    # The marker is the viewer's: no camera frame shows it.
    assert not any(_magenta(f.rgb).any() for f in first_ep.frames)

    # Episode 2 started from home again; the keys step the target exactly.
    first, last = second_ep.commands[0], second_ep.commands[-1]
    np.testing.assert_allclose(first.target, target[0], atol=1e-6)
    np.testing.assert_allclose(last.target[:3] - first.target[:3], [0.05, 0.0, -0.03], atol=1e-6)
    assert last.target[3] - first.target[3] == pytest.approx(np.radians(5))
    assert first.gripper == 1.0 and last.gripper == 0.0
    assert [m.source for m in second_ep.marks] == ["operator"]
    assert second_ep.poi[-1][0] - second_ep.poi[0][0] > 0.04
    assert {"/camera/color", "/camera/depth", "/robot/joint_states"} <= set(second_ep.topic_counts)


@pytest.mark.viewer
def test_discard_writes_nothing(tmp_path, display):
    code, stderr, out = _drive(tmp_path, display, ("Up", "x"))
    assert code == 2 and "discarded" in stderr
    assert not out.exists() and not (tmp_path / "kb.mcap.part").exists()


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) of each run of True in ``mask``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return list(zip(edges[::2], edges[1::2], strict=True))


@pytest.mark.viewer
def test_base_drives_while_a_key_is_held(tmp_path, display):
    """Real keys held down (X key down ... key up): Shift+Up drives forward at 0.2 m/s,
    letting Shift go (Up still down) 0.4 m/s, letting Up go stops the base; M marks, Enter
    keeps the log. Each phase is counted in simulated time (the recorder's status lines, one
    per simulated second): 2-3 s between the keys being sent whatever the machine's speed,
    at least 0.9 s in the log whatever a busy machine adds to a key's delivery."""
    with _recording(tmp_path, display, BASE_SCENE) as (out, env, win, err):
        assert "hold keys to drive" in "".join(err.seen)
        for action, key, sim_s in (
            ("keydown", "shift", 0.0),
            ("keydown", "Up", 2.5),
            ("keyup", "shift", 2.5),  # Up still held: full speed
            ("keyup", "Up", 2.5),
        ):
            subprocess.run(["xdotool", action, key], env=env, check=True)
            if sim_s:
                err.wait_sim(sim_s)
        _keys(env, win, "m", "Return")
        err.proc.wait(timeout=60)
        code, stderr = err.proc.returncode, err.rest()
    assert code == 0, stderr
    log = read_log(out)
    t = np.array([c.t for c in log.commands])
    target = np.array([c.target for c in log.commands])
    speed = np.hypot(*np.diff(target[:, :2], axis=0).T) / np.diff(t)
    slow, fast = np.isclose(speed, 0.2, atol=1e-6), np.isclose(speed, 0.4, atol=1e-6)
    # One drive: half speed, then (Shift up) full speed; before and after it the target
    # stands still: it stops leading the tick Up comes up.
    (s0, s1), (f0, f1) = _runs(slow) + _runs(fast)
    assert _runs(speed > 1e-6) == [(s0, f1)] and s1 == f0
    assert 0.9 <= t[s1] - t[s0] <= 3.5 and 0.9 <= t[f1] - t[f0] <= 3.5
    # Forward is +x (the base starts facing +x): no sideways drift, no turn.
    np.testing.assert_allclose(target[:, 1], 0.0, atol=1e-9)
    np.testing.assert_allclose(target[:, 3], 0.0, atol=1e-9)
    pt, poi = np.asarray(log.poi_t), np.asarray(log.poi)
    vx = np.diff(poi[:, 0]) / np.diff(pt)

    def at(time_s: float) -> int:
        return min(int(np.searchsorted(pt, time_s)), len(vx) - 1)

    # The base follows at the commanded speed.
    assert vx[at(t[s0]) : at(t[s1])].max() == pytest.approx(0.2, abs=0.01)
    assert vx[at(t[f0]) : at(t[f1])].max() == pytest.approx(0.4, abs=0.01)
    # Released, the base settles onto the target and stops: on it 1 s later.
    i = at(t[f1] + 1.0)
    assert abs(poi[i, 0] - target[f1, 0]) < 0.003 and abs(vx[i]) < 0.01
    assert poi[-1, 0] == pytest.approx(0.2 * (t[s1] - t[s0]) + 0.4 * (t[f1] - t[f0]), abs=0.003)
    assert [m.source for m in log.marks] == ["operator"]
    assert {"/camera/color", "/lidar/scan", "/robot/joint_states"} <= set(log.topic_counts)


# --- the base's driving, without a viewer --------------------------------------------------


def test_twist_from_the_keys_held():
    np.testing.assert_allclose(twist({KEY_UP}), [0.4, 0, 0])
    np.testing.assert_allclose(twist({KEY_UP, KEY_DOWN}), [0, 0, 0])  # opposite keys cancel
    np.testing.assert_allclose(twist({KEY_LEFT}), [0, 0.4, 0])
    np.testing.assert_allclose(twist({KEY_RIGHT, KEY_E}), [0, -0.4, -0.8])
    d = 0.4 / np.sqrt(2)  # a diagonal goes at the nominal speed
    np.testing.assert_allclose(twist({KEY_UP, KEY_LEFT}), [d, d, 0])
    np.testing.assert_allclose(twist({KEY_UP, KEY_Q, KEY_LEFT_SHIFT}), [0.2, 0, 0.4])
    np.testing.assert_allclose(twist({KEY_LEFT_SHIFT, ord("M")}), [0, 0, 0])


def test_a_base_acts_on_m_enter_x_per_press_and_drives_only_while_keys_are_held():
    assert [key_action(k, base=True)[0] for k in (ord("M"), KEY_ENTER, ord("X"))] == [
        "mark",
        "finish",
        "discard",
    ]
    for k in (KEY_UP, KEY_Q, ord("G"), KEY_PAGE_UP):  # no step per press, no gripper, no z
        assert key_action(k, base=True) == (None, None)
    kind, delta = key_action(KEY_UP, base=False)  # the arm: unchanged
    assert kind == "move" and delta is not None and delta[0] == pytest.approx(0.01)


def test_without_key_state_a_press_drives_for_the_hold_window():
    pressed = {KEY_UP: 1.0, KEY_Q: 1.2}
    assert held_from_presses(pressed, 1.0 + HOLD_S - 0.01) == {KEY_UP, KEY_Q}
    assert held_from_presses(pressed, 1.0 + HOLD_S + 0.01) == {KEY_Q}


class Drive:
    """The base in the rooms, driven by :class:`BaseDriver` one control tick at a time."""

    def __init__(self) -> None:
        self.sim = Sim(load_scene(BASE_SCENE))
        self.driver = BaseDriver(self.sim.poi(), self.sim.control_period)
        self.poi: list[np.ndarray] = []
        self.target: list[np.ndarray] = []

    def hold(self, keys: set[int], seconds: float) -> None:
        for _ in range(round(seconds / self.sim.control_period)):
            target = self.driver.update(keys, self.sim.poi())
            self.sim.step(PoiCommand(self.sim.t, target, 1.0))
            self.target.append(target)
            self.poi.append(self.sim.poi())

    def speed(self, seconds: float) -> float:
        """Mean speed of the base over the last ``seconds`` [m/s]."""
        n = round(seconds / self.sim.control_period)
        return float(np.hypot(*(self.poi[-1][:2] - self.poi[-1 - n][:2])) / seconds)

    def lead(self) -> float:
        return float(np.hypot(*(self.target[-1][:2] - self.poi[-1][:2])))


def test_base_drives_in_its_body_frame_stops_on_release_and_never_winds_up():
    d = Drive()
    # Forward 1.5 s: the target runs at 0.4 m/s along +x, the base follows ~9 cm behind.
    d.hold({KEY_UP}, 1.5)
    np.testing.assert_allclose(d.target[-1], [0.6, 0, 0, 0], atol=1e-9)
    assert d.speed(0.5) == pytest.approx(0.4, abs=0.005)
    assert 0.05 < d.lead() < MAX_LEAD_M
    x_release = d.poi[-1][0]
    # Released: the target stays put; the base coasts onto it and stops.
    d.hold(set(), 1.0)
    np.testing.assert_allclose(d.target[-1], [0.6, 0, 0, 0], atol=1e-9)
    assert d.lead() < 0.002 and d.speed(0.1) < 0.01
    assert 0.05 < d.poi[-1][0] - x_release < 0.1  # the coast: the servos' lag at 0.4 m/s
    # Shift: half speed.
    d.hold({KEY_UP, KEY_LEFT_SHIFT}, 1.5)
    assert d.target[-1][0] == pytest.approx(0.9, abs=1e-9)
    assert d.speed(0.5) == pytest.approx(0.2, abs=0.005)
    d.hold(set(), 1.0)
    # Turn left for 196 ticks at 0.8 rad/s: 89.8 degrees.
    d.hold({KEY_Q}, 1.96)
    d.hold(set(), 1.0)
    assert math.degrees(d.poi[-1][3]) == pytest.approx(89.8, abs=0.1)
    start = d.poi[-1].copy()
    # Forward is now +y, in the body frame.
    d.hold({KEY_UP}, 1.0)
    d.hold(set(), 1.0)
    np.testing.assert_allclose(d.poi[-1][:2] - start[:2], [0.0, 0.4], atol=0.003)
    # Into the north wall (inner face y = 1.45; the base is 0.25 m from centre to front):
    # the base stops at the wall and the target leads it by at most 0.3 m, not the 2 m
    # that holding Up for 5 s would integrate.
    d.hold({KEY_UP}, 5.0)
    assert d.poi[-1][1] == pytest.approx(1.2, abs=0.005)
    assert max(np.hypot(*(t[:2] - p[:2])) for t, p in zip(d.target, d.poi, strict=True)) <= (
        MAX_LEAD_M + 1e-9
    )
    assert d.target[-1][1] == pytest.approx(1.5, abs=0.01)
    # Released against the wall: the target drops back to the base, which stops pushing.
    d.hold(set(), 0.3)
    assert d.lead() < 0.005
    assert d.poi[-1][1] == pytest.approx(1.2, abs=0.005)


@pytest.mark.viewer
def test_mobile_manipulator_switches_base_and_arm_with_tab(tmp_path, display):
    """loco_manip's mobile manipulator: Up held drives the base (mode base, shown in the
    viewer); Tab, then Up and Page Up step the hand in the base's frame while the base
    stands; Enter keeps the log, whose commands carry both targets."""
    with _recording(tmp_path, display, "loco_manip") as (out, env, win, err):
        assert "Tab switches base/arm" in "".join(err.seen)
        # Up held for 1-2 s of simulation (status lines come once per simulated second, so
        # wait_sim(1.0) could end at once): the target runs 0.4-0.8 m. Released, the base
        # coasts onto it for about 1 s before Tab hands the keys to the arm.
        subprocess.run(["xdotool", "keydown", "Up"], env=env, check=True)
        err.wait_sim(2.0)
        subprocess.run(["xdotool", "keyup", "Up"], env=env, check=True)
        err.wait_sim(1.5)
        _keys(env, win, "Tab", "Up", "Up", "Up", "Prior", "Prior", "Tab", "Return")
        err.proc.wait(timeout=90)
        code, stderr = err.proc.returncode, err.rest()
    assert code == 0, stderr
    log = read_log(out)
    base = np.array([c.base for c in log.commands])
    hand = np.array([c.target for c in log.commands])
    assert base[-1, 0] - base[0, 0] > 0.2, "the base drove forward"
    np.testing.assert_allclose(base[:, 1], base[0, 1], atol=1e-4)  # straight ahead
    # Five key presses: 3 forward, 2 up, 1 cm each. Under load the viewer may handle
    # several presses in one tick, so count centimetres, not the ticks that moved: every
    # change is a whole number of steps forward or up, and they add up to 3 and 2.
    steps = np.diff(hand[:, :3], axis=0)
    moved = np.flatnonzero(np.linalg.norm(steps, axis=1) > 0)
    assert len(moved) >= 1
    cm = steps[moved] / 0.01
    np.testing.assert_allclose(cm, np.round(cm), atol=1e-6)
    assert (np.round(cm) >= 0).all() and (np.round(cm[:, 1]) == 0).all(), cm
    np.testing.assert_allclose(hand[-1, :3] - hand[0, :3], [0.03, 0.0, 0.02], atol=1e-9)
    # The hand stepped while the base stood (arm mode): its target stays within the 3 mm
    # the driver lets it settle by.
    assert np.ptp(base[moved[0] :, 0]) < 3e-3


@pytest.mark.viewer
def test_replay_teach_keyboard_continues_where_the_tree_stops(tmp_path, display):
    """``smc replay TREE --teach keyboard``: a pick_place tree taught only the cube stops
    at the root on a layout with the pyramid; the viewer opens on that state, the keys
    move the hand from where the robot stands (two marks, Enter), and the tree grows from
    the root by the taught log, its version one up and its history naming the node."""
    tree = tmp_path / "tree.json"
    compile_logs([SAMPLE_LOGS / "pick_place" / "demo1.mcap"], tree)  # the cube only
    before = load_tree(tree)
    scene = load_scene("pick_place")
    layout = next(lay for i in range(100) if "grey_pyramid" in (lay := layout_for(scene, 7, i)))
    layout_file = tmp_path / "layout.json"
    layout_file.write_text(json.dumps({k: list(v) for k, v in layout.items()}))
    env = {**os.environ, "DISPLAY": display, "MUJOCO_GL": "glfw"}
    cmd = [sys.executable, "-m", "smccli.cli", "replay", str(tree), "--layout", str(layout_file)]
    proc = subprocess.Popen(
        [*cmd, "--teach", "keyboard"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    err = Stderr(proc)
    try:
        err.wait_for("no contingent SMC at n0: the keyboard operator continues from here")
        err.wait_for("keyboard operator ready")
        win = _window(env)
        _focus(env, win)
        _keys(env, win, "Up", "Up", "Up")
        time.sleep(1.0)
        _keys(env, win, "m", *("Page_Down",) * 4)
        time.sleep(1.0)
        _keys(env, win, "m", "Return")
        proc.wait(timeout=120)
        stdout = proc.stdout.read() if proc.stdout else ""
        stderr = err.rest()
    finally:
        if proc.poll() is None:
            proc.kill()
    assert "taught at n0" in stdout, stdout + stderr
    taught = read_log(tmp_path / "tree_taught_n0_000.mcap")
    assert taught.metadata["teach_node"] == ROOT
    assert taught.metadata["teach_tree_digest"] == digest(before)
    # The keys stepped the target from where the hand stood: 3 cm along x, then 4 cm down.
    first, last = taught.commands[0], taught.commands[-1]
    np.testing.assert_allclose(first.target[:3], np.asarray(taught.poi[0])[:3], atol=0.005)
    np.testing.assert_allclose(last.target[:3] - first.target[:3], [0.03, 0, -0.04], atol=1e-6)
    assert len(taught.marks) == 2

    after = load_tree(tree)
    assert after.version == before.version + 1
    assert after.history[-1]["logs"][0]["at"] == ROOT
    new = [e for e in after.edges if e.sources[0].log == "tree_taught_n0_000.mcap"]
    assert new and new[0].parent == ROOT and len(after.children(ROOT)) == 2


def test_hud_shows_the_last_demonstrations_verdict() -> None:
    """After Enter the recorder checks the task; the next episode's HUD shows the verdict."""
    from smccli.record.hud import HudState, texts
    from smccli.record.session import task_line

    state = HudState("arm", 1.0, True, 0, np.zeros(4), np.zeros(4), episode=(2, 3))
    assert "last demo" not in texts(state)[0][2]
    failed = {"success": False, "reason": "white_box not resting inside orange_box"}
    verdict = task_line(failed)
    assert verdict == "task FAILED: white_box not resting inside orange_box"
    labels, values = texts(replace(state, last_task=verdict))[0][2:]
    assert labels.splitlines()[-1] == "last demo" and values.splitlines()[-1] == verdict
    assert task_line({"success": True}) == "task achieved"
    assert task_line({"success": None, "reason": "the scene defines no task"}) is None
