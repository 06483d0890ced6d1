"""Demonstrations of one task from different layouts merge into one tree (Algorithm 1,
eq. 31, 44): what a user teaching from many real demonstrations does. Every demonstration
here starts from its own random layout (``smc record --randomize --seed N``)."""

from __future__ import annotations

import itertools
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from conftest import SAMPLE_LOGS
from test_compile import BENCH_PICK, PICK_PLACE, WEIGH_SORT, check_weigh_sort, shape

from smccli.execute import campaign as cp
from smccli.learn.compile import compile_logs
from smccli.learn.tree import ROOT, Tree, load_tree
from smccli.logs import read_log
from smccli.record.session import RecordConfig, record
from smccli.workers import clean_context

pytestmark = pytest.mark.slow


N_BENCH = 4
"""bench_pick demonstrations, each from its own random layout (docs/figures.md's compile figure
has 100; 4 keep `make test` within its budget and still span the white box's ranges)."""
N_PAIRS = 4
"""weigh_sort light/heavy pairs, each demonstration from its own random layout (4 pairs,
8 demonstrations, already span both boxes' ranges; 6 cost `make test` 20 s more)."""


def _configs(root: Path, scene: str, script: str, seeds: range) -> list[RecordConfig]:
    return [
        RecordConfig(
            scene=scene,
            script=SAMPLE_LOGS / scene / script,
            seed=seed,
            output=root / f"{scene}_{Path(script).stem}_r{seed}.mcap",
            randomize=True,
        )
        for seed in seeds
    ]


@pytest.fixture(scope="module")
def demos(tmp_path_factory) -> dict[str, list[Path]]:
    """18 demonstrations, each from its own random layout, recorded on two processes (the
    recordings are independent; forked from a server that has only imported smc: EGL
    contexts do not survive fork)."""
    root = tmp_path_factory.mktemp("layouts")
    groups = {
        "bench_pick": _configs(root, "bench_pick", "demo.yaml", range(1, N_BENCH + 1)),
        "light": _configs(root, "weigh_sort", "demo_light.yaml", range(1, N_PAIRS + 1)),
        "heavy": _configs(root, "weigh_sort", "demo_heavy.yaml", range(1, N_PAIRS + 1)),
        "cube": _configs(root, "pick_place", "demo1.yaml", range(1, 4)),
        "pyramid": _configs(root, "pick_place", "demo2.yaml", range(1, 4)),
    }
    with ProcessPoolExecutor(2, mp_context=clean_context(["smccli.record.session"])) as pool:
        for summary in pool.map(record, [c for cfgs in groups.values() for c in cfgs]):
            assert not summary.interrupted
    return {k: [Path(c.output) for c in cfgs] for k, cfgs in groups.items()}


def _start(log: Path, name: str) -> np.ndarray:
    """Where ``name`` stood when the demonstration began (ground truth: evaluation only)."""
    _, poses = read_log(log, topics=["/sim/ground_truth"]).ground_truth[0]
    return poses[name]


def _assert_layouts_differ(logs: list[Path], name: str) -> None:
    """The test means something only if the demonstrations really start elsewhere."""
    starts = [_start(p, name) for p in logs]
    gaps = [np.hypot(*(a[:2] - b[:2])) for a, b in itertools.combinations(starts, 2)]
    assert np.median(gaps) > 0.08, gaps


def supports(tree: Tree) -> list:
    """Nested supports from the root, in the order of :func:`shape`."""

    def sub(node: str) -> list:
        return [(e.support, sub(e.child)) for e in tree.children(node)]

    return sub(ROOT)


def test_bench_pick_from_many_layouts_is_one_chain(demos, tmp_path):
    logs = demos["bench_pick"]
    _assert_layouts_differ(logs, "white_box")
    tree = compile_logs(logs, tmp_path / "tree.json").tree
    assert shape(tree) == BENCH_PICK
    assert supports(tree) == [(N_BENCH, [(N_BENCH, [])])]


def test_each_weigh_sort_pair_is_the_papers_tree(demos, tmp_path):
    _assert_layouts_differ(demos["light"] + demos["heavy"], "light_box")
    for k, pair in enumerate(zip(demos["light"], demos["heavy"], strict=True)):
        tree = compile_logs(list(pair), tmp_path / f"pair{k}.json").tree
        check_weigh_sort(tree)


@pytest.fixture(scope="module")
def weigh_sort_tree(demos, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("ws") / "tree.json"
    compile_logs(demos["light"] + demos["heavy"], path)
    return path


def test_weigh_sort_demos_from_many_layouts_share_their_first_smcs(weigh_sort_tree):
    tree = load_tree(weigh_sort_tree)
    assert shape(tree) == WEIGH_SORT
    n, k = 2 * N_PAIRS, N_PAIRS
    assert supports(tree) == [(n, [(n, [(k, [(k, [])]), (k, [(k, [])])])])]
    grasp = tree.children(ROOT)[0]
    weighed = tree.children(tree.children(grasp.child)[0].child)
    weights = sorted(e.smc.perception.weight for e in weighed)
    assert weights == [pytest.approx(0.1, abs=0.01), pytest.approx(0.5, abs=0.01)]


def test_weigh_sort_campaign_on_the_merged_tree(weigh_sort_tree):
    s = cp.run_campaign(weigh_sort_tree, trials=20, seed=11, workers=2)
    assert s["successes"] >= 19, s["failures"]


def test_pick_place_demos_merge_per_task_and_branch_at_the_root(demos, tmp_path):
    _assert_layouts_differ(demos["cube"], "orange_cube")
    logs = [p for pair in zip(demos["cube"], demos["pyramid"], strict=True) for p in pair]
    tree = compile_logs(logs, tmp_path / "tree.json").tree
    assert shape(tree) == PICK_PLACE
    assert supports(tree) == [(3, [(3, [])]), (3, [(3, [])])]
    cube, pyramid = tree.children(ROOT)
    cube_logs = {s.log for s in cube.sources}
    assert cube_logs == {p.name for p in demos["cube"]}
    assert {s.log for s in pyramid.sources} == {p.name for p in demos["pyramid"]}
