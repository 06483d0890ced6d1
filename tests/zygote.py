"""Run the real ``smc`` command in a fresh process that starts with smc already imported.

A command line run by the tests pays 1-3 s of imports (MuJoCo, open3d, scipy, rerun) before
it does anything; the suite runs a few hundred. A zygote process imports smc once; each
command is a child forked from it (its own process: its own working directory, output files,
exit code and interpreter exit, nothing shared with the next command), which then runs
``smccli.cli.main`` as ``python -m smccli.cli`` would. The zygote never creates a GL context,
a thread pool or a model, so what the child inherits is only imported code.

Commands may run side by side (``Zygote.start``: a robot and the node that drives it over
ROS), each with its own environment, and take signals as any process does. Tests that
need the interpreter's own start (the console entry point) start ``python -m smccli.cli``
themselves.

Protocol on the zygote's stdin/stdout, one JSON object per line: a request
``{"id", "argv", "cwd", "stdout", "stderr", "env"}`` (the two output file paths, which may
be one; ``env`` may be null: the zygote's own), answered by ``{"id", "pid"}`` when the child
starts and ``{"id", "rc"}`` (its exit code, negative for a signal) when it ends.
"""

from __future__ import annotations

import gc
import itertools
import json
import os
import select
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

PRELOAD = (
    "smccli.cli",
    "smccli.execute.campaign",
    "smccli.learn.compile",
    "smccli.learn.doctor",
    "smccli.record.session",
    "smccli.inspect.views",
    "smccli.logs.bag_topics",
)
"""What every command imports before it starts: the heavy part of its start-up."""


class Command:
    """A command forked from the zygote, as far as a test needs a ``subprocess.Popen``:
    its pid, signals, exit code and what it wrote."""

    def __init__(self, zygote: Zygote, ident: int, argv: list[str], out: Path, err: Path) -> None:
        self.args = ["smc", *argv]
        self._zygote, self._id, self._out, self._err = zygote, ident, out, err
        self.pid: int = zygote._reply(ident, "pid", None)
        self.returncode: int | None = None

    def poll(self) -> int | None:
        if self.returncode is None:
            self.returncode = self._zygote._reply(self._id, "rc", 0, wait=False)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        """The exit code; subprocess.TimeoutExpired after ``timeout`` [s] (it runs on)."""
        if self.returncode is None:
            rc = self._zygote._reply(self._id, "rc", timeout)
            if rc is None:
                raise subprocess.TimeoutExpired(self.args, timeout or 0)
            self.returncode = rc
        return self.returncode

    def send_signal(self, sig: int) -> None:
        if self.poll() is None:
            os.kill(self.pid, sig)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)

    def communicate(self, timeout: float | None = None) -> tuple[str, str]:
        """Wait for the end (as :meth:`wait`), then its stdout and stderr."""
        self.wait(timeout)
        return self.output()

    def output(self) -> tuple[str, str]:
        out = self._out.read_text(errors="replace")
        return out, (out if self._err == self._out else self._err.read_text(errors="replace"))


class Zygote:
    """A zygote process (started on first use) and the commands forked from it."""

    def __init__(self, env: dict[str, str], repo: Path) -> None:
        self.env, self.repo = env, repo
        self.proc: subprocess.Popen[bytes] | None = None
        self._replies: dict[int, dict] = {}
        self._changed = threading.Condition()
        self._ids = itertools.count()

    def _start(self) -> subprocess.Popen[bytes]:
        with self._changed:
            if self.proc is None or self.proc.poll() is not None:
                self.proc = subprocess.Popen(
                    [sys.executable, __file__, str(self.repo)],
                    stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE,
                    env=self.env,
                    cwd=self.repo,
                )
                assert self.proc.stdout is not None
                assert json.loads(self.proc.stdout.readline()) == {"ready": True}
                self._replies.pop(-1, None)  # an earlier zygote's end
                threading.Thread(target=self._read, args=(self.proc,), daemon=True).start()
            return self.proc

    def _read(self, proc: subprocess.Popen[bytes]) -> None:
        """The zygote's replies, filed by request id (a thread of its own)."""
        assert proc.stdout is not None
        for line in proc.stdout:
            reply = json.loads(line)
            with self._changed:
                self._replies.setdefault(reply.pop("id"), {}).update(reply)
                self._changed.notify_all()
        with self._changed:  # the zygote ended: no reply will come
            self._replies.setdefault(-1, {})["ended"] = proc.wait()
            self._changed.notify_all()

    def _reply(self, ident: int, key: str, timeout: float | None, wait: bool = True):  # noqa: ANN202
        """Reply ``key`` of request ``ident``; None when it has not come within ``timeout``
        [s] (or at once, without ``wait``)."""
        with self._changed:
            if wait:
                self._changed.wait_for(
                    lambda: key in self._replies.get(ident, {}) or -1 in self._replies, timeout
                )
            if key not in self._replies.get(ident, {}) and -1 in self._replies:
                raise RuntimeError(f"the zygote ended (exit {self._replies[-1]['ended']})")
            return self._replies.get(ident, {}).get(key)

    def start(
        self,
        argv: list[str],
        cwd: Path,
        stdout: Path,
        stderr: Path,
        env: dict[str, str] | None = None,
    ) -> Command:
        """``python -m smccli.cli ARGV`` started in ``cwd`` with ``env`` (default: the
        zygote's), writing to ``stdout`` and ``stderr`` (they may be one file)."""
        proc = self._start()
        assert proc.stdin is not None
        ident = next(self._ids)
        request = {
            "id": ident,
            "argv": argv,
            "cwd": str(cwd),
            "stdout": str(stdout),
            "stderr": str(stderr),
            "env": env,
        }
        with self._changed:
            proc.stdin.write((json.dumps(request) + "\n").encode())
            proc.stdin.flush()
        return Command(self, ident, argv, Path(stdout), Path(stderr))

    def run(self, argv: list[str], cwd: Path, timeout: float) -> subprocess.CompletedProcess[str]:
        """``python -m smccli.cli ARGV`` in ``cwd``: its exit code and its output."""
        with tempfile.TemporaryDirectory() as tmp:
            cmd = self.start(argv, cwd, Path(tmp, "stdout"), Path(tmp, "stderr"))
            try:
                rc = cmd.wait(timeout)
            except subprocess.TimeoutExpired:
                cmd.kill()
                cmd.wait()
                raise subprocess.TimeoutExpired(argv, timeout) from None
            return subprocess.CompletedProcess(argv, rc, *cmd.output())

    def close(self) -> None:
        """Close the zygote's input: it ends once its running commands have."""
        if self.proc is not None and self.proc.poll() is None:
            assert self.proc.stdin is not None
            self.proc.stdin.close()
            self.proc.wait(timeout=60)


def _child(request: dict) -> None:
    """In the forked child: become ``python -m smccli.cli ARGV``; never returns."""
    signal.set_wakeup_fd(-1)
    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
    if request.get("env") is not None:
        os.environ.clear()
        os.environ.update(request["env"])
    os.chdir(request["cwd"])
    out = os.open(request["stdout"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    err = out
    if request["stderr"] != request["stdout"]:
        err = os.open(request["stderr"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    null = os.open(os.devnull, os.O_RDONLY)
    for fd, new in ((0, null), (1, out), (2, err)):
        os.dup2(new, fd)
    for new in {null, out, err}:
        os.close(new)
    sys.stdin = open(0, closefd=False)  # noqa: SIM115 - the process's stdin until it exits
    import smccli.cli as cli

    sys.argv = [cli.__file__, *request["argv"]]
    # Leaves through SystemExit: the interpreter's own exit (atexit handlers, flushes).
    cli.main()
    sys.exit(0)


def _account(argv: list[str], wall: float, usage: os.struct_rusage) -> None:
    """With ``SMC_CMDLOG`` set, append the command's argv, wall time and CPU time [s] (its
    own and that of the children it waited for; not a campaign's Dask workers) as a JSON
    line: where the suite's commands spend their time (docs/testing.md)."""
    log = os.environ.get("SMC_CMDLOG")
    if log:
        cpu = usage.ru_utime + usage.ru_stime
        with open(log, "a") as f:
            f.write(json.dumps({"argv": argv, "wall_s": wall, "cpu_s": cpu}) + "\n")


def _serve() -> None:
    """The zygote: import, then fork one child per request line, several at a time, and
    answer each child's end, until stdin closes and the last child has ended."""
    sys.path.insert(0, sys.argv[1])
    import importlib

    for name in PRELOAD:
        importlib.import_module(name)
    # The imported objects leave the collector's generations: a child's collections do not
    # visit (and so write to) them, and fewer of the zygote's pages are copied per child.
    gc.freeze()
    wake_r, wake_w = os.pipe()  # SIGCHLD wakes the select below
    os.set_blocking(wake_w, False)
    signal.set_wakeup_fd(wake_w)
    signal.signal(signal.SIGCHLD, lambda *_: None)

    def reply(message: dict) -> None:
        os.write(1, (json.dumps(message) + "\n").encode())

    reply({"ready": True})
    running: dict[int, tuple[int, list[str], float]] = {}  # pid -> id, argv, start
    pending, reading = b"", True
    while reading or running:
        ready, _, _ = select.select([0, wake_r] if reading else [wake_r], [], [], 1.0)
        if wake_r in ready:
            os.read(wake_r, 4096)
        while running:
            pid, status, usage = os.wait4(-1, os.WNOHANG)
            if pid == 0:
                break
            ident, argv, start = running.pop(pid)
            _account(argv, time.perf_counter() - start, usage)
            reply({"id": ident, "rc": os.waitstatus_to_exitcode(status)})
        if 0 in ready:
            chunk = os.read(0, 65536)
            reading = bool(chunk)
            pending += chunk
            while b"\n" in pending:
                line, pending = pending.split(b"\n", 1)
                request = json.loads(line)
                pid = os.fork()
                if pid == 0:
                    os.close(wake_r)
                    os.close(wake_w)
                    _child(request)
                running[pid] = (request["id"], request["argv"], time.perf_counter())
                reply({"id": request["id"], "pid": pid})


if __name__ == "__main__":
    _serve()
