"""``smc compile``: tree shapes of the sample tasks (paper 4.1, 4.3, 5.1), versioning,
idempotence, the honesty rule, and one-line errors that leave the tree untouched."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from smccli.errors import LogError, TreeError
from smccli.learn.compile import compile_logs
from smccli.learn.segmentation import SegmentMode
from smccli.learn.tree import ROOT, Tree, load_tree
from smccli.logs import read_log, strip_topic


def shape(tree: Tree) -> list:
    """Nested (event, children) of the tree from the root, children in creation order."""

    def sub(node: str) -> list:
        return [(e.smc.action.event, sub(e.child)) for e in tree.children(node)]

    return sub(ROOT)


PICK_PLACE = [("close", [("open", [])]), ("close", [("open", [])])]
BENCH_PICK = [("close", [("open", [])])]
WEIGH_SORT = [("close", [("open", [("close", [("open", [])]), ("close", [("open", [])])])])]


def check_pick_place(tree: Tree) -> None:
    # Paper 4.1: same actions on different objects -> two branches from the root.
    assert shape(tree) == PICK_PLACE
    a, b = tree.children(ROOT)
    assert a.smc.perception.cluster is not None and b.smc.perception.cluster is not None
    assert all(e.support == 1 for e in tree.edges)


def check_weigh_sort(tree: Tree) -> None:
    # Paper 4.3: grasp and weigh merge (support 2); the weight splits the rest.
    assert shape(tree) == WEIGH_SORT
    first = tree.children(ROOT)[0]
    second = tree.children(first.child)[0]
    assert first.support == 2 and second.support == 2
    third = tree.children(second.child)
    weights = sorted(e.smc.perception.weight for e in third)
    assert weights[0] == pytest.approx(0.1, abs=0.01) and weights[1] == pytest.approx(0.5, abs=0.01)
    # The two places go to different goals: the bins, 27 cm apart.
    places = [tree.children(e.child)[0].smc.perception.cluster.centroid for e in third]
    assert abs(places[0][0] - places[1][0]) > 0.2


def check_bench_pick(tree: Tree) -> None:
    assert shape(tree) == BENCH_PICK


CHECKS = {
    "pick_place": check_pick_place,
    "weigh_sort": check_weigh_sort,
    "bench_pick": check_bench_pick,
}


@pytest.mark.parametrize("scene", list(CHECKS))
def test_sample_trees(sample_trees, scene):
    CHECKS[scene](load_tree(sample_trees[scene]))


@pytest.mark.parametrize("seed", [1])
@pytest.mark.parametrize("scene", list(CHECKS))
def test_structure_holds_for_other_recordings(reseeded_logs, tmp_path, scene, seed):
    tree = compile_logs(reseeded_logs[seed][scene], tmp_path / "tree.json").tree
    CHECKS[scene](tree)


def test_recompile_is_idempotent_and_new_log_bumps_version(sample_logs, reseeded_logs, tmp_path):
    out = tmp_path / "tree.json"
    first = compile_logs(sample_logs["bench_pick"], out)
    assert first.changed and first.tree.version == 1
    text = out.read_text()
    again = compile_logs(sample_logs["bench_pick"], out)
    assert not again.changed and again.skipped == tuple(sample_logs["bench_pick"])
    assert out.read_text() == text
    more = compile_logs([*sample_logs["bench_pick"], *reseeded_logs[1]["bench_pick"]], out)
    assert more.changed and more.tree.version == 2
    doc = json.loads(out.read_text())
    assert [h["version"] for h in doc["history"]] == [1, 2]
    assert doc["edges"][0]["support"] == 2  # the same task demonstrated twice merges


def test_same_inputs_give_the_same_digest(sample_logs, tmp_path):
    compile_logs(sample_logs["pick_place"], tmp_path / "a.json")
    compile_logs(sample_logs["pick_place"], tmp_path / "b.json")
    a = json.loads((tmp_path / "a.json").read_text())
    b = json.loads((tmp_path / "b.json").read_text())
    assert a["digest"] == b["digest"] and a["edges"] == b["edges"]


def _edges_without_sources(path: Path) -> list:
    doc = json.loads(path.read_text())
    return [{k: v for k, v in e.items() if k != "sources"} for e in doc["edges"]]


def test_ground_truth_is_never_read(sample_logs, tmp_path):
    """Honesty rule: dropping /sim/ground_truth from the logs gives the same tree."""
    stripped = []
    for p in sample_logs["weigh_sort"]:
        dst = tmp_path / p.name
        strip_topic(p, dst, "/sim/ground_truth")
        stripped.append(dst)
    compile_logs(sample_logs["weigh_sort"], tmp_path / "with.json")
    compile_logs(stripped, tmp_path / "without.json")
    assert _edges_without_sources(tmp_path / "with.json") == _edges_without_sources(
        tmp_path / "without.json"
    )


def test_params_differing_from_the_tree_are_refused(sample_logs, reseeded_logs, tmp_path):
    out = tmp_path / "tree.json"
    compile_logs(sample_logs["bench_pick"], out)
    before = out.read_bytes()
    with pytest.raises(TreeError, match="--rebuild"):
        compile_logs(reseeded_logs[1]["bench_pick"], out, overrides=["t_hp=0.3"])
    assert out.read_bytes() == before
    rebuilt = compile_logs(sample_logs["bench_pick"], out, overrides=["t_hp=0.3"], rebuild=True)
    assert rebuilt.tree.params.t_hp == 0.3 and rebuilt.tree.version == 2


def test_bad_logs_leave_the_tree_untouched(sample_logs, tmp_path):
    out = tmp_path / "tree.json"
    compile_logs(sample_logs["bench_pick"], out)
    before = out.read_bytes()
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"this is not an mcap file at all")
    no_depth = tmp_path / "no_depth.mcap"
    strip_topic(sample_logs["pick_place"][0], no_depth, "/camera/depth")
    for bad, message in [
        (garbage, "garbage.mcap"),
        (no_depth, "/camera/depth missing"),
        (tmp_path / "absent.mcap", "absent.mcap"),
    ]:
        with pytest.raises(LogError, match=message):
            compile_logs([*sample_logs["bench_pick"], bad], out)
        assert out.read_bytes() == before


def test_cli_error_is_one_line_with_exit_code_2(sample_logs, tmp_path):
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"\x89not mcap")
    out = tmp_path / "tree.json"
    proc = subprocess.run(
        [sys.executable, "-m", "smccli.cli", "compile", str(garbage), "-o", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "garbage.mcap" in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr and not out.exists()


def test_cli_prints_the_tree(sample_logs, tmp_path):
    out = tmp_path / "tree.json"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "smccli.cli",
            "compile",
            *map(str, sample_logs["bench_pick"]),
            "-o",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        env={**__import__("os").environ, "COLUMNS": "200"},
    )
    assert proc.returncode == 0, proc.stderr
    assert "version 1" in proc.stdout and "e1" in proc.stdout and "e2" in proc.stdout
    assert "white object" in proc.stdout and "orange object" in proc.stdout


def test_truncated_log_compiles_up_to_its_last_whole_chunk(sample_logs, tmp_path):
    """A log cut short (killed recorder) is read up to its last whole chunk, with a warning."""
    src = sample_logs["bench_pick"][0]
    cut = tmp_path / "cut.mcap"
    data = src.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.97)])
    warnings: list[str] = []
    result = compile_logs([cut], tmp_path / "tree.json", on_warning=warnings.append)
    assert any("cut.mcap" in w and "trunc" in w.lower() for w in warnings), warnings
    assert len(result.tree.edges) >= 1
    dropped = [w for w in warnings if "complete fragment(s)" in w]
    assert len(dropped) == 1 and "dropped the last" in dropped[0], warnings


def test_truncated_log_keeps_only_complete_fragments(sample_logs, tmp_path):
    """Cut inside the second fragment: only the first (closed by its mark) is compiled."""
    src = sample_logs["bench_pick"][0]
    whole = compile_logs([src], tmp_path / "whole.json")
    frag1, frag2 = whole.added[0].fragments
    data = src.read_bytes()
    warnings: list[str] = []
    # Find a cut whose last whole chunk lies inside the second fragment.
    for frac in np.linspace(0.95, 0.3, 14):
        cut = tmp_path / f"cut{frac:.2f}.mcap"
        cut.write_bytes(data[: int(len(data) * frac)])
        t_last = read_log(cut, on_warning=lambda _m: None).poi_t[-1]
        if frag1.t1 + 0.5 < t_last < frag2.t1 - 0.5:
            break
    else:
        pytest.fail("no cut inside the second fragment")
    result = compile_logs([cut], tmp_path / "tree.json", on_warning=warnings.append)
    (chain,) = result.added
    assert len(chain.fragments) == 1 and chain.fragments[0].t1 == pytest.approx(frag1.t1)
    assert len(result.tree.edges) == 1
    note = next(w for w in warnings if "complete fragment(s)" in w)
    assert f"dropped the last {t_last - frag1.t1:.1f} s" in note, note


def test_truncated_log_without_a_boundary_is_an_error(sample_logs, tmp_path):
    src = sample_logs["bench_pick"][0]
    whole = compile_logs([src], tmp_path / "whole.json")
    t_mark = whole.added[0].fragments[0].t1
    data = src.read_bytes()
    for frac in np.linspace(0.5, 0.05, 10):
        cut = tmp_path / "early.mcap"
        cut.write_bytes(data[: int(len(data) * frac)])
        try:
            log = read_log(cut, on_warning=lambda _m: None)
        except LogError:
            continue
        if len(log.poi_t) and log.poi_t[-1] < t_mark - 0.5:
            break
    else:
        pytest.fail("no cut before the first mark")
    with pytest.raises(LogError, match="no complete fragment"):
        compile_logs([cut], tmp_path / "tree.json", on_warning=lambda _m: None)
    assert not (tmp_path / "tree.json").exists()


@pytest.mark.parametrize("mode", [SegmentMode.auto, SegmentMode.both])
@pytest.mark.parametrize("scene", list(CHECKS))
def test_automatic_segmentation_finds_the_same_structure(sample_logs, tmp_path, scene, mode):
    """Without the operator's marks, gripper and scale events cut the same fragments."""
    tree = compile_logs(sample_logs[scene], tmp_path / "tree.json", segment_mode=mode).tree
    CHECKS[scene](tree)


def test_concurrent_compiles_serialise_on_the_lock(sample_logs, reseeded_logs, tmp_path):
    """Two processes adding different logs to one tree: both land, the file stays valid."""
    out = tmp_path / "tree.json"
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", "smccli.cli", "compile", str(log), "-o", str(out)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        for log in (sample_logs["bench_pick"][0], reseeded_logs[1]["bench_pick"][0])
    ]
    for p in procs:
        assert p.wait(timeout=300) == 0, p.stderr.read()
    tree = load_tree(out)
    assert tree.version == 2 and tree.edges[0].support == 2
    assert not (tmp_path / "tree.json.part").exists()
    assert not (tmp_path / "tree.json.lock").exists(), "a finished compile leaves no lock"
