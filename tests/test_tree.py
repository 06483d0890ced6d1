"""Algorithm 1 (tree building), merging, the tree file and its guarantees."""

from __future__ import annotations

import functools
import json
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from smccli.errors import TreeError
from smccli.learn.contingency import c_f, d_a, d_p, match_context, merge
from smccli.learn.frames import goal_from_object, goal_in_object
from smccli.learn.params import SmcParams, with_overrides
from smccli.learn.smc import (
    SalientPerceptions,
    Smc,
    Source,
    action_from_path,
)
from smccli.learn.tree import ROOT, Tree, digest, insert_chain, load_tree, save_tree, tree_to_dict
from smccli.perception import Cluster

PARAMS = SmcParams()


def _hist(hot: int, n: int = 39) -> np.ndarray:
    h = np.full(n, 0.002)
    h[hot] = 1.0
    return h / h.sum()


def _cluster(hot: int, x: float = 0.5, y: float = 0.0, size=(0.05, 0.05, 0.05)) -> Cluster:
    return Cluster(
        centroid=np.array([x, y, size[2] / 2]),
        yaw=0.3,
        yaw_period=math.pi / 2,
        extents=np.array(size),
        histogram=_hist(hot),
        n_points=400,
    )


def _path(start, goal, lift: float = 0.1, n: int = 150) -> tuple[np.ndarray, np.ndarray]:
    s = np.linspace(0, 1, n)
    mj = 10 * s**3 - 15 * s**4 + 6 * s**5
    y = np.asarray(start)[None, :] + mj[:, None] * (np.asarray(goal) - np.asarray(start))[None, :]
    y[:, 2] += lift * np.sin(np.pi * s)
    return s * 2.0, y


@functools.cache
def _smc(
    hot: int | None,
    goal=(0.5, 0.0, 0.03, 0.3),
    event=("open", "close"),
    weight: float | None = None,
    lift: float = 0.1,
) -> Smc:
    start = np.array([0.3, 0.0, 0.3, 0.0])
    t, y = _path(start, np.array(goal), lift)
    cluster = None if hot is None else _cluster(hot, goal[0], goal[1])
    opening = {"open": 1.0, "close": 0.0}
    grip = np.full(len(t), opening[event[0]])
    grip[-1] = opening[event[1]]  # the event at the fragment's end
    return Smc(
        SalientPerceptions(cluster=cluster, weight=weight),
        action_from_path(t, y, grip, cluster, PARAMS),
    )


def _src(i: int) -> Source:
    return Source(log=f"demo{i}.mcap", sha256=f"{i:064x}", t0=float(i), t1=float(i + 1))


def test_same_smc_is_contingent_and_different_object_is_not():
    a, b = _smc(3), _smc(3)
    assert d_p(a.perception, b.perception, PARAMS) < 1e-9
    assert d_a(a.action, b.action, PARAMS) < 1e-6
    assert c_f(a, b, PARAMS)
    other = _smc(20)
    assert d_p(a.perception, other.perception, PARAMS) > PARAMS.t_hp
    assert not c_f(a, other, PARAMS)


def test_gripper_event_and_goal_frame_make_actions_incomparable():
    a = _smc(3)
    assert d_a(a.action, _smc(3, event=("close", "open")).action, PARAMS) == math.inf
    assert d_a(a.action, _smc(None).action, PARAMS) == math.inf


def test_goal_far_away_is_a_different_action():
    a, b = _smc(None), _smc(None, goal=(0.5, 0.2, 0.03, 0.3))
    assert d_a(a.action, b.action, PARAMS) > 0.15


def test_object_goal_maps_to_a_moved_and_turned_object():
    cluster = _cluster(3, 0.5, 0.1)
    goal_w = np.array([0.52, 0.11, 0.04, 0.5])
    local = goal_in_object(goal_w, cluster)
    moved = Cluster(
        centroid=np.array([0.3, -0.2, 0.025]),
        yaw=cluster.yaw + 1.0,
        yaw_period=cluster.yaw_period,
        extents=cluster.extents,
        histogram=cluster.histogram,
        n_points=100,
    )
    back = goal_from_object(local, moved, near_yaw=0.5 + 1.0)
    # The offset turned with the object, and the yaw is the demonstrated one + 1 rad.
    off = goal_w[:2] - cluster.centroid[:2]
    c, s = math.cos(1.0), math.sin(1.0)
    np.testing.assert_allclose(
        back[:2], moved.centroid[:2] + [c * off[0] - s * off[1], s * off[0] + c * off[1]], atol=1e-9
    )
    assert back[3] == pytest.approx(1.5)


def test_goal_yaw_uses_symmetry_to_turn_the_wrist_least():
    cluster = _cluster(3)  # square footprint: period pi/2
    local = goal_in_object(np.array([0.5, 0.0, 0.03, 0.3]), cluster)  # dyaw = 0
    g = goal_from_object(local, cluster, near_yaw=0.3 + 2 * math.pi / 2 - 0.1)
    assert abs(g[3] - (0.3 + math.pi)) < 1e-9


@pytest.mark.parametrize("turn", [0.08, -0.08])
def test_offset_stays_on_the_taught_side_when_the_yaw_wraps(turn):
    # A bar handle (period pi) taught at yaw pi/2 - 1 mrad; its cluster's centre sits 15 mm
    # behind the bar (the posts), so the grasp is 15 mm in front of it. Turned 0.08 rad,
    # the footprint's yaw wraps to the other end of [-pi/2, pi/2), and the gripper's pi
    # gives the same wrist yaw from both object yaws: the taught yaw settles the side.
    bar = replace(_cluster(3, size=(0.16, 0.05, 0.02)), yaw=math.pi / 2 - 1e-3, yaw_period=math.pi)
    goal_w = np.array([bar.centroid[0] - 0.015, bar.centroid[1], bar.centroid[2], math.pi / 2])
    local = goal_in_object(goal_w, bar)
    now_yaw = math.remainder(bar.yaw + turn, math.pi)
    now = replace(bar, yaw=now_yaw)
    g = goal_from_object(local, now, near_yaw=0.0, taught_yaw=bar.yaw)
    expect = bar.centroid[:2] - 0.015 * np.array([math.cos(turn), math.sin(turn)])
    np.testing.assert_allclose(g[:2], expect, atol=1e-9)


def test_pick_place_demos_give_two_root_edges():
    # Paper 4.1: same actions on different objects -> two branches from the root.
    tree = Tree(params=PARAMS)
    tree = insert_chain(
        tree,
        [_smc(3), _smc(10, goal=(0.5, 0.3, 0.12, 0.0), event=("close", "open"))],
        [_src(1), _src(2)],
    )
    tree = insert_chain(
        tree,
        [_smc(25), _smc(33, goal=(0.5, 0.3, 0.12, 0.0), event=("close", "open"))],
        [_src(3), _src(4)],
    )
    assert len(tree.children(ROOT)) == 2
    assert len(tree.edges) == 4 and len(tree.nodes) == 5


def test_weigh_sort_demos_share_two_edges_then_branch():
    # Paper 4.3: grasp and weigh merge; the weight sends the rest to different bins.
    def chain(w, bin_y):
        return [
            _smc(3, weight=0.0),
            _smc(12, goal=(0.5, 0.05, 0.09, 0.0), event=("close", "open"), weight=0.0),
            _smc(3, goal=(0.5, 0.05, 0.025, 0.0), weight=w),
            _smc(20, goal=(0.4, bin_y, 0.15, 0.0), event=("close", "open"), weight=w),
        ]

    tree = Tree(params=PARAMS)
    tree = insert_chain(tree, chain(0.1, 0.3), [_src(i) for i in range(4)])
    tree = insert_chain(tree, chain(0.5, -0.3), [_src(i) for i in range(10, 14)])
    first = tree.children(ROOT)
    assert len(first) == 1 and first[0].support == 2
    second = tree.children(first[0].child)
    assert len(second) == 1 and second[0].support == 2
    third = tree.children(second[0].child)
    assert len(third) == 2 and all(e.support == 1 for e in third)
    assert {round(e.smc.perception.weight, 2) for e in third} == {0.1, 0.5}
    assert len(second[0].sources) == 2


@settings(max_examples=30, deadline=None)
@given(
    st.lists(st.lists(st.sampled_from([3, 10, 25]), min_size=1, max_size=4), min_size=1, max_size=5)
)
def test_tree_invariants(chains):
    """Every fragment is counted once, supports add up, every chain is a root path."""
    tree = Tree(params=PARAMS)
    n = 0
    for chain in chains:
        tree = insert_chain(
            tree, [_smc(h) for h in chain], [_src(n + k) for k in range(len(chain))]
        )
        n += len(chain)
    assert sum(e.support for e in tree.edges) == n
    assert sum(len(e.sources) for e in tree.edges) == n
    children = {e.child for e in tree.edges}
    assert ROOT not in children and len(children) == len(tree.edges)
    assert set(tree.nodes) == children | {ROOT}
    for chain in chains:  # replaying each chain by perception walks a root path of its length
        node = ROOT
        for h in chain:
            nxt = [e for e in tree.children(node) if c_f(_smc(h), e.smc, PARAMS)]
            assert nxt
            node = nxt[0].child


def test_merge_is_support_weighted():
    a = _smc(3, weight=0.1)
    b = _smc(3, weight=0.2)
    m = merge(a, b, 3, 1)
    assert m.perception.weight == pytest.approx(0.125)
    assert m.perception.cluster.histogram.sum() == pytest.approx(1.0)


def test_match_context_picks_the_most_similar_cluster():
    stored = _smc(10).perception
    clusters = [_cluster(3, 0.4, 0.1), _cluster(10, 0.6, -0.2), _cluster(25)]
    m = match_context(stored, clusters, None, PARAMS)
    assert m.cluster_index == 1 and m.contingent
    m2 = match_context(stored, [clusters[0], clusters[2]], None, PARAMS)
    assert not m2.contingent and m2.d_p > PARAMS.t_hp


def test_file_round_trip_and_digest(tmp_path):
    tree = insert_chain(
        Tree(params=PARAMS), [_smc(3), _smc(None, event=("close", "open"))], [_src(1), _src(2)]
    )
    path = tmp_path / "tree.json"
    save_tree(tree, path)
    back = load_tree(path)
    assert digest(back) == digest(tree)
    assert tree_to_dict(back) == tree_to_dict(tree)
    assert not (tmp_path / "tree.json.part").exists()


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d.update(format="other"), "not an smc tree"),
        (lambda d: d.update(schema_version=99), "schema_version 99"),
        (lambda d: d["edges"][0].update(support=5), "digest mismatch"),
        (lambda d: d["edges"][0].pop("action"), "invalid at edges/0"),
    ],
)
def test_bad_tree_files_are_refused(tmp_path, mutate, message):
    tree = insert_chain(Tree(params=PARAMS), [_smc(3)], [_src(1)])
    doc = tree_to_dict(tree)
    mutate(doc)
    path = tmp_path / "tree.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(TreeError, match=message):
        load_tree(path)


def test_garbage_and_missing_tree(tmp_path):
    with pytest.raises(TreeError, match="no such tree file"):
        load_tree(tmp_path / "nope.json")
    bad = tmp_path / "bad.json"
    bad.write_bytes(b"\x00\x01garbage{")
    with pytest.raises(TreeError, match="not valid JSON"):
        load_tree(bad)


def test_overrides():
    p = with_overrides(PARAMS, ["t_hp=0.2", "dmp.n_basis=50"])
    assert p.t_hp == 0.2 and p.dmp.n_basis == 50
    from smccli.errors import SmcError

    with pytest.raises(SmcError, match="unknown parameter 'nope'"):
        with_overrides(PARAMS, ["nope=1"])
    with pytest.raises(SmcError, match="KEY=VALUE"):
        with_overrides(PARAMS, ["t_hp"])
