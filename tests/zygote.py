"""Run the real ``smc`` command in a fresh process that starts with smc already imported.

A command line run by the tests pays 1-3 s of imports (MuJoCo, open3d, scipy, rerun) before
it does anything; the suite runs a few hundred. A zygote process imports smc once; each
command is a child forked from it (its own process: its own working directory, output files,
exit code and interpreter exit, nothing shared with the next command), which then runs
``smccli.cli.main`` as ``python -m smccli.cli`` would. The zygote never creates a GL context,
a thread pool or a model, so what the child inherits is only imported code.

Tests that need the command's own process start (signals, an interrupted recorder, the
console entry point) start ``python -m smccli.cli`` themselves.

Protocol on the zygote's stdin/stdout, one JSON object per line: a request
``{"argv", "cwd", "stdout", "stderr"}`` (the two output file paths), answered by
``{"pid"}`` when the child starts and ``{"rc"}`` (its exit code, negative for a signal)
when it ends.
"""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import tempfile
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


class Zygote:
    """A zygote process (started on first use) and the commands forked from it."""

    def __init__(self, env: dict[str, str], repo: Path) -> None:
        self.env, self.repo = env, repo
        self.proc: subprocess.Popen[str] | None = None
        self._pending = b""  # the zygote's replies read but not yet used

    def _start(self) -> subprocess.Popen[str]:
        if self.proc is None or self.proc.poll() is not None:
            self.proc = subprocess.Popen(
                [sys.executable, __file__, str(self.repo)],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                text=True,
                env=self.env,
                cwd=self.repo,
            )
            self._pending = b""
            assert self._line(None) == {"ready": True}
        return self.proc

    def _line(self, timeout: float | None) -> dict:
        """The zygote's next reply; TimeoutError if none comes within ``timeout`` [s].
        Read from the pipe's descriptor: a buffered reader could hold the reply that
        ``select`` waits for."""
        assert self.proc is not None and self.proc.stdout is not None
        fd = self.proc.stdout.fileno()
        while b"\n" not in self._pending:
            ready, _, _ = select.select([fd], [], [], timeout)
            if not ready:
                raise TimeoutError
            chunk = os.read(fd, 65536)
            if not chunk:
                raise RuntimeError(f"the zygote ended (exit {self.proc.wait()})")
            self._pending += chunk
        line, self._pending = self._pending.split(b"\n", 1)
        return json.loads(line)

    def run(self, argv: list[str], cwd: Path, timeout: float) -> subprocess.CompletedProcess[str]:
        """``python -m smccli.cli ARGV`` in ``cwd``: its exit code and its output."""
        proc = self._start()
        assert proc.stdin is not None
        with tempfile.TemporaryDirectory() as tmp:
            out, err = Path(tmp, "stdout"), Path(tmp, "stderr")
            request = {"argv": argv, "cwd": str(cwd), "stdout": str(out), "stderr": str(err)}
            proc.stdin.write(json.dumps(request) + "\n")
            proc.stdin.flush()
            pid = self._line(None)["pid"]
            try:
                rc = self._line(timeout)["rc"]
            except TimeoutError:
                os.kill(pid, signal.SIGKILL)
                self._line(None)
                raise subprocess.TimeoutExpired(argv, timeout) from None
            return subprocess.CompletedProcess(
                argv, rc, out.read_text(errors="replace"), err.read_text(errors="replace")
            )

    def close(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            assert self.proc.stdin is not None
            self.proc.stdin.close()
            self.proc.wait(timeout=30)


def _child(request: dict) -> None:
    """In the forked child: become ``python -m smccli.cli ARGV``; never returns."""
    os.chdir(request["cwd"])
    for fd, path, flags in (
        (0, os.devnull, os.O_RDONLY),
        (1, request["stdout"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC),
        (2, request["stderr"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC),
    ):
        new = os.open(path, flags, 0o644)
        os.dup2(new, fd)
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
    """The zygote: import, then fork one child per request line until stdin closes."""
    sys.path.insert(0, sys.argv[1])
    import importlib

    for name in PRELOAD:
        importlib.import_module(name)
    reply = sys.stdout
    print(json.dumps({"ready": True}), file=reply, flush=True)
    for line in sys.stdin:
        request = json.loads(line)
        pid = os.fork()
        if pid == 0:
            _child(request)
        print(json.dumps({"pid": pid}), file=reply, flush=True)
        start = time.perf_counter()
        _, status, usage = os.wait4(pid, 0)
        _account(request["argv"], time.perf_counter() - start, usage)
        print(json.dumps({"rc": os.waitstatus_to_exitcode(status)}), file=reply, flush=True)


if __name__ == "__main__":
    _serve()
