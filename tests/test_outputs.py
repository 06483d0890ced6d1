"""Outputs: every command refuses an output it cannot write before any work, never
overwrites without ``--force``, and writes its files atomically."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import SAMPLE_LOGS, sha256, smc

from smccli.errors import OutputError, OutputExistsError
from smccli.outputs import ExclusiveLock, check_output, write_atomic

LOG = SAMPLE_LOGS / "bench_pick" / "demo.mcap"
SCRIPT = SAMPLE_LOGS / "bench_pick" / "demo.yaml"


@pytest.fixture(scope="module")
def tree(sample_trees) -> Path:
    return sample_trees["bench_pick"]


@pytest.fixture
def unwritable(tmp_path) -> Path:
    """A folder where no file can be created: a read-only folder, or (as root, whom
    permissions do not stop) /sys, where the kernel refuses new files."""
    if os.geteuid() == 0:
        return Path("/sys")
    d = tmp_path / "ro"
    d.mkdir()
    d.chmod(0o500)
    return d


def commands(tree: Path, out: Path) -> dict[str, list[str]]:
    """Each command with ``out`` as its output."""
    return {
        "record": ["record", "--scene", "bench_pick", "--script", str(SCRIPT), "-o", str(out)],
        "compile": ["compile", str(LOG), "-o", str(out)],
        "replay log": ["replay", str(tree), "--seed", "3", "-o", str(out)],
        "replay report": ["replay", str(tree), "--seed", "3", "--report", str(out)],
        "campaign report": ["replay", str(tree), "--trials", "4", "--report", str(out)],
        "inspect": ["inspect", str(tree), "--save", str(out)],
    }


NAMES = list(commands(Path("t"), Path("o")))


def _one_line(proc: subprocess.CompletedProcess) -> str:
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert len(lines) == 1, proc.stderr
    return lines[0]


@pytest.mark.parametrize("name", NAMES)
def test_missing_folder_is_refused(tree, tmp_path, name):
    out = tmp_path / "nowhere" / "out.file"
    line = _one_line(smc(*commands(tree, out)[name]))
    assert str(out) in line and "does not exist" in line
    assert not (tmp_path / "nowhere").exists()


@pytest.mark.parametrize("name", NAMES)
def test_unwritable_folder_is_refused(tree, unwritable, name):
    out = unwritable / "smc-out.file"
    line = _one_line(smc(*commands(tree, out)[name]))
    assert str(out) in line and "not writable" in line
    assert not out.exists()


@pytest.mark.parametrize("name", [n for n in NAMES if n != "compile"])
def test_existing_output_is_kept_without_force(tree, tmp_path, name):
    out = tmp_path / "existing.file"
    out.write_bytes(b"what the user had\n")
    line = _one_line(smc(*commands(tree, out)[name]))
    assert str(out) in line and "--force" in line
    assert out.read_bytes() == b"what the user had\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["existing.file"]


def test_compile_adds_to_an_existing_tree_but_refuses_a_non_tree(tmp_path):
    out = tmp_path / "notes.json"
    out.write_text('{"mine": true}\n')
    before = sha256(out)
    line = _one_line(smc("compile", str(LOG), "-o", str(out)))
    assert "notes.json" in line and "not an smc tree" in line
    assert sha256(out) == before


def test_unfinished_recording_is_never_overwritten(tmp_path):
    """A leftover ``.part`` is a killed recorder's only copy of a demonstration."""
    out = tmp_path / "demo.mcap"
    part = tmp_path / "demo.mcap.part"
    part.write_bytes(b"half a demonstration")
    line = _one_line(smc(*commands(Path("t"), out)["record"]))
    assert "demo.mcap.part" in line and "doctor" in line
    assert part.read_bytes() == b"half a demonstration" and not out.exists()


def test_check_output_library_errors(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(OutputExistsError, match="--force"):
        check_output(tmp_path / "f")
    assert check_output(tmp_path / "f", force=True) == tmp_path / "f"
    with pytest.raises(OutputError, match="is a directory"):
        check_output(tmp_path, force=True)
    with pytest.raises(OutputError, match="is not a folder"):
        check_output(tmp_path / "f" / "g")


def test_write_atomic_replaces_whole_or_not_at_all(tmp_path):
    target = tmp_path / "report.json"
    target.write_text("old\n")
    write_atomic(target, "new\n")
    assert target.read_text() == "new\n"
    with pytest.raises(TypeError):
        write_atomic(target, 42)  # type: ignore[arg-type]
    assert target.read_text() == "new\n"
    assert [p.name for p in tmp_path.iterdir()] == ["report.json"]  # no temp file left


_COUNTER = """
import sys
from pathlib import Path
from smccli.outputs import ExclusiveLock
lock, counter, n = ExclusiveLock(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3])
for _ in range(n):
    lock.acquire(timeout=120)
    counter.write_text(str(int(counter.read_text()) + 1))
    lock.release()
"""


def test_exclusive_lock_excludes_and_leaves_no_file(tmp_path):
    """Three processes add 1 to a counter 150 times each under the lock: no update lost,
    though every release removes the lock file (a locker that got a removed file retries)."""
    lock, counter = tmp_path / "c.lock", tmp_path / "c.txt"
    counter.write_text("0")
    procs = [
        subprocess.Popen([sys.executable, "-c", _COUNTER, str(lock), str(counter), "150"])
        for _ in range(3)
    ]
    assert [p.wait(timeout=300) for p in procs] == [0, 0, 0]
    assert counter.read_text() == "450"
    assert not lock.exists()


def test_exclusive_lock_times_out_while_held(tmp_path):
    held = ExclusiveLock(tmp_path / "t.lock")
    held.acquire(timeout=1)
    holder = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from smccli.outputs import ExclusiveLock as L\n"
            "try:\n    L(sys.argv[1]).acquire(timeout=0.3)\n"
            "except TimeoutError as e:\n    print(e); sys.exit(3)",
            str(tmp_path / "t.lock"),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert holder.returncode == 3 and "t.lock" in holder.stdout
    held.release()
    assert not (tmp_path / "t.lock").exists()
    again = ExclusiveLock(tmp_path / "t.lock")
    again.acquire(timeout=1)
    again.release()
