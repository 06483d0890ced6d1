"""Running Rerun's viewers: the native viewer (``--spawn``), and the web viewer
(``--serve``) as a process of the ``rerun`` binary shipped with rerun-sdk (the Python API
binds every interface; the binary takes ``--bind``) on its ports, stopped on Ctrl-C."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
import urllib.parse
import urllib.request
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from smccli.errors import SmcError
from smccli.inspect.plan import APP_ID, blueprint_for, fill, recording_plan
from smccli.learn.tree import Tree

if TYPE_CHECKING:
    from smccli.logs.log import Log


def rerun_binary() -> str:
    """Path of the ``rerun`` executable shipped with rerun-sdk (or ``RERUN_CLI_PATH``)."""
    if os.environ.get("RERUN_CLI_PATH"):
        return os.environ["RERUN_CLI_PATH"]
    import rerun_cli

    exe = Path(rerun_cli.__file__).parent / "rerun"
    if not exe.is_file():
        found = shutil.which("rerun")
        if found is None:
            raise SmcError(f"rerun binary not found at {exe} nor on PATH (reinstall rerun-sdk)")
        return found
    return str(exe)


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _port_taken(port: int) -> bool:
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return True
    return False


def _stop(proc: subprocess.Popen[bytes]) -> None:
    """Stop ``proc`` and its process group: SIGTERM, then SIGKILL after 5 s."""
    if proc.poll() is not None:
        return
    for sig, wait in ((signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(wait)
            break
        except subprocess.TimeoutExpired:
            continue


@dataclass(frozen=True, slots=True)
class Addresses:
    """Where ``--serve`` serves (both on 127.0.0.1)."""

    viewer: str
    """The web viewer's page, with the data address in its query: open this."""
    data: str
    """The gRPC proxy the page reads the recordings from (forward its port too)."""


def spawn_viewer(
    tree: Tree,
    logs: Sequence[Log],
    *,
    tree_name: str = "tree.json",
    warn: Callable[[str], None] = lambda m: None,
) -> list[str]:
    """Send the recordings to a native viewer (spawned if none listens on 9876)."""
    import rerun as rr

    plan = recording_plan(tree, logs, tree_name)
    bp = blueprint_for(tree, logs)
    for rid, log in plan:
        rec = rr.RecordingStream(APP_ID, recording_id=rid)
        try:
            rec.spawn(default_blueprint=bp)
        except Exception as exc:  # no display, no viewer binary
            raise SmcError(
                f"--spawn: cannot start Rerun's viewer ({exc}); use --save or --serve"
            ) from None
        rec.send_recording_name(rid)
        fill(rec, tree, log, warn)
        rec.flush()
    return [rid for rid, _ in plan]


def serve_recordings(
    tree: Tree,
    logs: Sequence[Log],
    *,
    port: int,
    grpc_port: int | None = None,
    tree_name: str = "tree.json",
    warn: Callable[[str], None] = lambda m: None,
    on_message: Callable[[str], None] | None = None,
    ready_timeout: float = 60.0,
    until: Callable[[], bool] | None = None,
) -> Addresses:
    """Serve the recordings with Rerun's web viewer on 127.0.0.1:``port`` (data on
    ``grpc_port``, a free port if None) until Ctrl-C (or ``until()``).

    The recordings are sent to the viewer's gRPC proxy one after the other, the first log's
    last: the viewer selects each recording as it arrives, so the page opens on the first
    log's (the tree's when there is no log), whatever the timing. ``on_message`` hears the
    two addresses once everything is sent; on Ctrl-C the viewer process (and its group) is
    stopped.
    """
    grpc = _grpc_port(port, grpc_port)
    data = f"rerun+http://127.0.0.1:{grpc}/proxy"
    addresses = Addresses(
        viewer=f"http://127.0.0.1:{port}/?url=" + urllib.parse.quote(data, safe=""),
        data=data,
    )
    # Ctrl-C must reach us: a shell's `cmd &` may start us with SIGINT ignored.
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    with tempfile.TemporaryDirectory(prefix="smc-serve-") as tmp:
        log_path = Path(tmp) / "viewer.log"
        with open(log_path, "wb") as viewer_log:
            proc = subprocess.Popen(
                _viewer_command(port, grpc),
                stdin=subprocess.DEVNULL,
                stdout=viewer_log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
            try:
                _wait_ready(proc, log_path, port, grpc, ready_timeout)
                _send_recordings(tree, logs, addresses.data, tree_name, warn)
                if on_message is not None:
                    on_message(f"viewer: {addresses.viewer}")
                    on_message(f"data:   {addresses.data}")
                    on_message(
                        f"(over SSH: ssh -L {port}:127.0.0.1:{port} -L {grpc}:127.0.0.1:{grpc}"
                        " HOST; Ctrl-C to stop)"
                    )
                while proc.poll() is None and not (until is not None and until()):
                    time.sleep(0.2)
                if proc.returncode not in (None, 0):
                    raise SmcError(f"rerun web viewer exited with code {proc.returncode}")
            except KeyboardInterrupt:
                if on_message is not None:
                    on_message("stopping the web viewer")
            finally:
                _stop(proc)
                signal.signal(signal.SIGINT, old)
    return addresses


def _grpc_port(port: int, grpc_port: int | None) -> int:
    """The data port: ``grpc_port``, or a free one if None. Raises SmcError for a port out
    of range, already in use, or the same as ``port``."""
    for flag, p in (("--port", port), ("--grpc-port", grpc_port)):
        if p is None:
            continue
        if not 0 < p < 65536:
            raise SmcError(f"{flag} {p}: expected 1-65535")
        if _port_taken(p):
            raise SmcError(f"{flag} {p}: 127.0.0.1:{p} is already in use")
    if grpc_port == port:
        raise SmcError(f"--grpc-port {grpc_port}: the same as --port")
    return grpc_port if grpc_port is not None else free_port()


def _viewer_command(port: int, grpc: int) -> list[str]:
    """The ``rerun`` command serving the web viewer on ``port`` and its data on ``grpc``."""
    return [
        rerun_binary(),
        "--serve-web",
        "--bind",
        "127.0.0.1",
        "--port",
        str(grpc),
        "--web-viewer-port",
        str(port),
    ]


def _send_recordings(
    tree: Tree,
    logs: Sequence[Log],
    data: str,
    tree_name: str,
    warn: Callable[[str], None],
) -> None:
    """Send each recording to the gRPC proxy at ``data``, the first log's last."""
    import rerun as rr

    bp = blueprint_for(tree, logs)
    for rid, log in reversed(recording_plan(tree, logs, tree_name)):
        rec = rr.RecordingStream(APP_ID, recording_id=rid)
        rec.connect_grpc(data, default_blueprint=bp)
        rec.send_recording_name(rid)
        fill(rec, tree, log, warn)
        rec.flush()
        rec.disconnect()


def _wait_ready(
    proc: subprocess.Popen[bytes], log_path: Path, port: int, grpc: int, timeout: float
) -> None:
    """Wait until the viewer's page answers and its gRPC port accepts connections."""
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + timeout
    while True:
        if proc.poll() is not None:
            tail = log_path.read_text(errors="replace").strip().splitlines()
            raise SmcError(
                f"rerun web viewer exited with code {proc.returncode}"
                f" ({tail[-1] if tail else 'no output'})"
            )
        try:
            with urllib.request.urlopen(url, timeout=1.0):
                pass
            with socket.create_connection(("127.0.0.1", grpc), timeout=1.0):
                return
        except OSError:
            if time.monotonic() > deadline:
                raise SmcError(
                    f"rerun web viewer did not answer on {url} within {timeout:.0f} s"
                ) from None
            time.sleep(0.2)
