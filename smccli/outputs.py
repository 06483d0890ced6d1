"""Output files: refused before any work starts when they cannot be written; written atomically.

Every command checks its outputs first (``check_output``), so a long recording or campaign
never ends in "cannot write" with its work lost, and writes them through ``write_atomic``
(temp file beside the target, fsync, rename), so a crash never leaves a half-written file
where a good one was.
"""

from __future__ import annotations

import fcntl
import os
import tempfile
import time
from pathlib import Path

from smccli.errors import OutputError, OutputExistsError


def check_output(path: str | os.PathLike[str], *, force: bool = False) -> Path:
    """Refuse ``path`` as an output unless it can be written: its folder exists and is
    writable, it is not a folder, and it does not exist (or ``force``).

    Raises OutputExistsError / OutputError naming the file and the problem.
    """
    p = Path(path)
    if p.is_dir():
        raise OutputError(f"{p}: is a directory, expected a file to write")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.exists():
        raise OutputError(f"{p}: folder {parent} does not exist")
    if not parent.is_dir():
        raise OutputError(f"{p}: {parent} is not a folder")
    try:
        # Probe by creating a file: access(2) says yes to root even where the kernel or a
        # read-only mount will refuse the write.
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as exc:
        raise OutputError(f"{p}: folder {parent} is not writable ({exc.strerror})") from None
    if p.exists():
        if not force:
            raise OutputExistsError(f"{p}: exists (use --force to overwrite)")
        if not os.access(p, os.W_OK):
            raise OutputError(f"{p}: exists and is not writable")
    return p


def write_atomic(path: str | os.PathLike[str], data: str | bytes) -> Path:
    """Replace ``path`` with ``data`` atomically: a temp file in the same folder, fsync, rename.

    Readers see the old file or the new one, never a part; the temp file is removed on error.
    """
    p = Path(path)
    raw = data.encode("utf-8") if isinstance(data, str) else data
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".part", dir=p.parent or ".")
    try:
        # mkstemp makes the file 0600; give it the mode a plain open() would (0666 - umask).
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)
        with os.fdopen(fd, "wb") as f:
            f.write(raw)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return p


class ExclusiveLock:
    """An exclusive lock on a file created for it and removed when released (flock(2)).

    By hand rather than filelock: its Unix lock leaves the file behind, and removing a lock
    file on release is only safe when every locker checks, once it holds the lock, that the
    path still names the file it locked (else a waiter on the removed file and a newcomer
    on a new one would both "hold" it).
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self._fd: int | None = None

    def acquire(self, timeout: float) -> None:
        """Block until held; TimeoutError after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                while True:
                    try:
                        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                        break
                    except BlockingIOError:
                        if time.monotonic() > deadline:
                            raise TimeoutError(f"{self.path}: held by another process") from None
                        time.sleep(0.05)
                try:
                    same = os.stat(self.path).st_ino == os.fstat(fd).st_ino
                except FileNotFoundError:
                    same = False
            except BaseException:
                os.close(fd)
                raise
            if same:
                self._fd = fd
                return
            os.close(fd)  # the holder before us removed it: lock the new file

    def release(self) -> None:
        """Remove the file, then let go (a waiter on it retries on a fresh file)."""
        if self._fd is None:
            return
        self.path.unlink(missing_ok=True)
        os.close(self._fd)
        self._fd = None
