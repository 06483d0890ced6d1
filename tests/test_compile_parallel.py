"""``smc compile --workers N``: logs read and extracted in worker processes give the tree, the
warnings and the first error of a compile in process (``workers=1``); a bad log still aborts
with its one-line error before the tree is touched."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import SAMPLE_LOGS, sha256, smc

from smccli.errors import LogError
from smccli.learn.compile import compile_logs
from smccli.logs import read_log

PICK_PLACE = sorted((SAMPLE_LOGS / "pick_place").glob("*.mcap"))


def tree_doc(path: Path) -> dict:
    """The tree file without the compile's wall-clock time."""
    doc = json.loads(path.read_text())
    for entry in doc["history"]:
        entry.pop("time")
    return doc


def compiled(logs: list[Path], out: Path, workers: int) -> tuple[dict, list[str], list[str]]:
    warnings: list[str] = []
    result = compile_logs(logs, out, workers=workers, on_warning=warnings.append)
    return tree_doc(out), warnings, [p.name for p in result.skipped]


def test_workers_give_the_tree_of_a_compile_in_process(tmp_path: Path) -> None:
    # A copy of a log is read but skipped (already in the tree), wherever it was read.
    again = tmp_path / "again.mcap"
    shutil.copyfile(PICK_PLACE[0], again)
    logs = [*PICK_PLACE, again]
    one = compiled(logs, tmp_path / "one.json", workers=1)
    two = compiled(logs, tmp_path / "two.json", workers=2)
    assert one == two
    assert one[2] == ["again.mcap"] and len(one[0]["edges"]) == 4


@pytest.fixture(scope="module")
def cut_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A pick_place log cut before its first mark: it reads (truncated, with a warning) and
    then has no complete fragment, an error raised while extracting."""
    src = PICK_PLACE[0]
    t_mark = next(m.t for m in read_log(src).marks if m.source == "operator")
    data = src.read_bytes()
    cut = tmp_path_factory.mktemp("cut") / "early.mcap.part"
    for frac in np.linspace(0.5, 0.05, 10):
        cut.write_bytes(data[: int(len(data) * frac)])
        try:
            log = read_log(cut, on_warning=lambda _m: None)
        except LogError:
            continue
        if len(log.poi_t) and log.poi_t[-1] < t_mark - 0.5:
            return cut
    pytest.fail("no cut before the first mark")


def test_the_first_bad_log_in_order_aborts_and_leaves_the_tree(
    tmp_path: Path, cut_log: Path
) -> None:
    tree = tmp_path / "tree.json"
    compile_logs(PICK_PLACE[:1], tree, workers=1)
    before = sha256(tree)
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"this is not an mcap file at all")
    # The cut log fails while extracting, the garbage while reading: the cut one comes first.
    logs = [PICK_PLACE[1], cut_log, garbage]
    errors = {}
    for workers in (1, 2):
        warnings: list[str] = []
        with pytest.raises(LogError) as exc:
            compile_logs(logs, tree, workers=workers, on_warning=warnings.append)
        errors[workers] = (str(exc.value), warnings)
        assert sha256(tree) == before
    message, warnings = errors[2]
    assert errors[1] == errors[2]
    assert "\n" not in message and message.startswith(f"{cut_log}: truncated"), message
    assert "no complete fragment to compile" in message
    assert any(w.startswith(f"{cut_log}: truncated at byte") for w in warnings), warnings


def test_cli_with_workers_refuses_a_bad_log_in_one_line(tmp_path: Path) -> None:
    tree = tmp_path / "tree.json"
    compile_logs(PICK_PLACE[:1], tree, workers=1)
    before = sha256(tree)
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"\x89not mcap")
    proc = smc("compile", PICK_PLACE[1], garbage, "--workers", "2", "-o", tree)
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and len(lines) == 1, proc.stderr
    assert lines[0].startswith("error: ") and str(garbage) in lines[0], lines[0]
    assert sha256(tree) == before
