"""Failure causes of a replay, provoked for real: a tree edited so its grasp closes above
the box (grasp_missed) or its release happens far from the container (placed_outside /
object_dropped). The classification reads only the trace and the final poses."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from smccli.execute.episode import layout_for, run_episode
from smccli.learn.tree import ROOT, Tree, load_tree
from smccli.world.scene import load_scene


def _shift_goal(tree: Tree, edge_id: str, delta: tuple[float, float, float]) -> Tree:
    edges = []
    for e in tree.edges:
        if e.id == edge_id:
            a = e.smc.action
            goal = a.goal.copy()
            goal[:3] += np.asarray(delta)
            smc = dataclasses.replace(e.smc, action=dataclasses.replace(a, goal=goal))
            e = dataclasses.replace(e, smc=smc)
        edges.append(e)
    return dataclasses.replace(tree, edges=tuple(edges))


@pytest.fixture(scope="module")
def bench_tree(sample_trees) -> Tree:
    return load_tree(sample_trees["bench_pick"])


def test_unedited_tree_succeeds(bench_tree):
    result = run_episode(bench_tree, seed=3)
    assert result.outcome == "success" and result.success


def test_closing_above_the_box_is_a_missed_grasp(bench_tree):
    grasp = bench_tree.children(ROOT)[0].id
    result = run_episode(_shift_goal(bench_tree, grasp, (0.0, 0.0, 0.12)), seed=3)
    assert not result.success and result.outcome == "grasp_missed", result.reason


def test_releasing_beside_the_container_is_a_placement_failure(bench_tree):
    first = bench_tree.children(ROOT)[0]
    place = bench_tree.children(first.child)[0].id
    scene = load_scene("bench_pick")
    layout = layout_for(scene, 3)
    result = run_episode(_shift_goal(bench_tree, place, (-0.25, 0.0, 0.0)), layout=layout)
    assert not result.success
    assert result.outcome in ("placed_outside", "object_dropped"), result.reason
