"""The keyboard operator, driven for real: MuJoCo's viewer under Xvfb, keys sent by xdotool."""

from __future__ import annotations

import os
import queue
import re
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from smccli.logs import read_log

pytestmark = pytest.mark.viewer


@pytest.fixture
def display():
    if not (shutil.which("Xvfb") and shutil.which("xdotool")):
        pytest.fail("Xvfb and xdotool are needed (make setup installs them)")
    for n in range(90, 140):
        if not os.path.exists(f"/tmp/.X11-unix/X{n}") and not os.path.exists(f"/tmp/.X{n}-lock"):
            break
    xvfb = subprocess.Popen(
        ["Xvfb", f":{n}", "-screen", "0", "1280x1024x24", "-nolisten", "tcp"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 10
    while not os.path.exists(f"/tmp/.X11-unix/X{n}"):
        assert time.monotonic() < deadline, "Xvfb did not start"
        time.sleep(0.1)
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
        self.seen.append(line)
        m = STATUS.search(line)
        if m:
            self.sim_t = float(m.group(1))
        return line

    def wait_for(self, text: str, timeout: float = 90.0) -> None:
        deadline = time.monotonic() + timeout
        while True:
            line = self._next(deadline)
            if line is not None and text in line:
                return

    def wait_sim(self, seconds: float, timeout: float = 300.0) -> None:
        """Wait until the recorder has simulated ``seconds`` more: what happens in the scene
        follows simulated time, which a busy machine stretches against the wall clock."""
        deadline = time.monotonic() + timeout
        until = self.sim_t + seconds
        while self.sim_t < until:
            self._next(deadline)

    def rest(self) -> str:
        self.thread.join(timeout=30)
        while not self.lines.empty():
            self.seen.append(self.lines.get())
        return "".join(self.seen)


def _record(tmp_path, display):
    out = tmp_path / "kb.mcap"
    env = {**os.environ, "DISPLAY": display, "MUJOCO_GL": "glfw"}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "smccli.cli",
            "record",
            "--scene",
            "pick_place",
            "--operator",
            "keyboard",
            "-o",
            str(out),
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    return out, env, proc


def _drive(tmp_path, display, *presses: tuple[str, ...]) -> tuple[int, str, Path]:
    """Record with the keyboard operator, pressing each group of keys (at least 1.5 s of
    simulation between groups, so the gripper can close); returns (exit code, stderr,
    output path)."""
    out, env, proc = _record(tmp_path, display)
    err = Stderr(proc)
    try:
        err.wait_for("keyboard operator ready")
        win = _window(env)
        _focus(env, win)
        for group in presses[:-1]:
            _keys(env, win, *group)
            err.wait_sim(2.0)  # status lines come once per simulated second
        _keys(env, win, *presses[-1])
        proc.wait(timeout=60)
        return proc.returncode, err.rest(), out
    finally:
        if proc.poll() is None:
            proc.kill()


def test_keys_move_the_target_toggle_the_gripper_and_mark(tmp_path, display):
    code, stderr, out = _drive(
        tmp_path, display, ("Up",) * 5 + ("Page_Down",) * 3 + ("q", "g"), ("m", "Return")
    )
    assert code == 0, stderr
    log = read_log(out)
    first, last = log.commands[0], log.commands[-1]
    np.testing.assert_allclose(last.target[:3] - first.target[:3], [0.05, 0.0, -0.03], atol=1e-6)
    assert last.target[3] - first.target[3] == pytest.approx(np.radians(5))
    assert first.gripper == 1.0 and last.gripper == 0.0
    assert [m.source for m in log.marks] == ["operator"]
    # The robot followed: the POI moved forward and down with the target.
    assert log.poi[-1][0] - log.poi[0][0] > 0.04
    assert {"/camera/color", "/camera/depth", "/robot/joint_states"} <= set(log.topic_counts)


def test_discard_writes_nothing(tmp_path, display):
    code, stderr, out = _drive(tmp_path, display, ("Up", "x"))
    assert code == 2 and "discarded" in stderr
    assert not out.exists() and not (tmp_path / "kb.mcap.part").exists()
