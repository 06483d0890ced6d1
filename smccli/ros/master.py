"""A ROS 1 master of its own (:func:`roscore`): 127.0.0.1, a free port, its logs in a
folder of the caller's. The bench and the tests run ``smc sim`` and ``smc run`` on it."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import time
import xmlrpc.client
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


@contextmanager
def roscore(home: Path, timeout: float = 60.0) -> Iterator[dict[str, str]]:
    """A roscore on 127.0.0.1 at a free port, stopped (SIGINT, then SIGKILL) on exit;
    yields the environment that reaches it (``ROS_MASTER_URI``, ``ROS_IP``, ``ROS_HOME``
    and ``ROS_LOG_DIR`` under ``home``, this checkout on ``PYTHONPATH``). RuntimeError when
    the master does not answer within ``timeout`` seconds."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {
        **os.environ,
        "ROS_MASTER_URI": f"http://127.0.0.1:{port}",
        "ROS_IP": "127.0.0.1",
        "ROS_HOSTNAME": "127.0.0.1",
        "ROS_HOME": str(home),
        "ROS_LOG_DIR": str(home / "log"),
        "PYTHONPATH": str(REPO),
        "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
    }
    core = subprocess.Popen(
        ["roscore", "-p", str(port)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        master = xmlrpc.client.ServerProxy(env["ROS_MASTER_URI"])
        deadline = time.monotonic() + timeout
        while True:
            try:
                master.getSystemState("/smc")
                break
            except OSError:
                if core.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError("roscore did not start") from None
                time.sleep(0.2)
        yield env
    finally:
        core.send_signal(signal.SIGINT)
        try:
            core.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(core.pid, signal.SIGKILL)
            core.wait()
