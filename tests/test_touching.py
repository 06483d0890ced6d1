"""Objects touching one another (issue 38): the white box with a grey box of its size
against it is one cluster to DBSCAN, and its pieces divided by colour or height
(:func:`~smccli.perception.cluster_splits`) hold the white box again. Real renders of the
look-alike family's trials (development seed 0); ground truth only in assertions."""

from __future__ import annotations

import dataclasses
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from conftest import TWIN_THRESHOLD, first_view  # noqa: E402

from smccli.bench import lookalike as la  # noqa: E402
from smccli.perception import (  # noqa: E402
    cluster_splits,
    cluster_windows,
    clusters_from_frame,
    d_cluster,
)
from smccli.perception.params import scene_perception  # noqa: E402
from smccli.perception.splits import windows  # noqa: E402

T_HP = 0.1
TOUCHING = (35, 56, 90)
"""Trials of seed 0 whose grey look-alike (0.37, 0.58, 0.40) touches the white box (gap
under 20 µm) and that stopped at the first decision with ``no_contingent_smc`` before
splits (docs/bench_lookalike.json at c0757ca)."""
ANGLED = (71,)
"""Trial of seed 0 whose grey look-alike (0.63) meets the white box's end at an angle (an
L, 0.6 mm apart) and that still stopped with splits by brightness and height alone (at
7d5f948): the local direction divides them."""

ENDS = (48, 156, 196)
"""Trials of development seed 2 whose grey look-alike (0.61-0.62) touches the white box
and that stopped with ``no_contingent_smc`` at fabc2e9: every cluster or piece holding the
white box was 16-17 cm long, where the demonstration's was 14."""

SIDE = 107
"""Trial of seed 0 that stopped with ``no_contingent_smc`` at b59ba97: the grey look-alike
(0.55) along the white box's side made every piece holding the white box 5-6 cm wide,
where the demonstration's was 4."""


@pytest.fixture(scope="module")
def whole():
    """The white box's view alone: trial 35's layout with the look-alike out of the way."""
    draw = la.draw_trial(la.learning_scene(), 0, TOUCHING[0])
    scene = la.learning_scene()
    layout = {**draw.layout, la.REPLACED: [0.7, 0.4, 0.025, 0.0]}
    frame, robot = first_view(scene, layout)
    params = scene_perception(scene)
    white = np.asarray(layout[la.TARGET])
    c = min(clusters_from_frame(frame, robot, params), key=lambda k: _off(k, white))
    assert _off(c, white) < 0.01
    return c, params


def _taught(tree_file):
    """The taught perception of the grasp of the tree in ``tree_file``."""
    from smccli.learn.tree import load_tree

    tree = load_tree(tree_file)
    return next(e for e in tree.edges if e.smc.action.event == "close").smc.perception.cluster


def _exact(params):
    """``params`` without the extent tolerance: the case the windows were made for. With
    it (stop 54) the white box's own piece passes first in seed 0's 107 and seed 2's 156
    (D_P 0.096, 0.097; on the white box, as the windows' are)."""
    return dataclasses.replace(params, extent_tolerance=0.0)


def _size(cluster) -> tuple[float, float]:
    return float(cluster.extents[0]), float(cluster.extents[1])


def _off(cluster, pose) -> float:
    return float(np.hypot(*(cluster.centroid[:2] - np.asarray(pose)[:2])))


def _trial_view(draw, folder):
    """(layout, camera frame, robot geometry) of the look-alike family's trial ``draw``
    before the robot moves; its scene is written to ``folder``."""
    folder.mkdir()
    layout = {**draw.layout, la.LOOKALIKE: draw.pose}
    return layout, *first_view(la.trial_scene(draw, folder), layout)


def _white_box_and_not_the_lookalike(candidates, taught, params, draw, layout, near) -> None:
    """The candidate nearest ``taught`` is within T_hP and on the white box; none within
    ``near`` [m] of the look-alike (and 4 cm from the white box) is within T_hP."""
    trial = f"trial {draw.index}"
    d, best = min(((d_cluster(c, taught, params), c) for c in candidates), key=lambda t: t[0])
    assert d < T_HP, f"{trial}: best D_P {d:.3f}"
    assert _off(best, layout[la.TARGET]) < 0.01, f"{trial}: {best.centroid}"
    for c in candidates:
        if _off(c, draw.pose) < near and _off(c, layout[la.TARGET]) > 0.04:
            assert d_cluster(c, taught, params) >= T_HP, f"{trial}: {c.centroid}"


def test_a_piece_of_the_merged_cluster_is_the_white_box(whole, tmp_path):
    view, params = whole
    for i in TOUCHING:
        draw = la.draw_trial(la.learning_scene(), 0, i)
        assert draw.gap < 0.001
        layout, frame, robot = _trial_view(draw, tmp_path / str(i))
        seen = clusters_from_frame(frame, robot, params)
        assert min(d_cluster(c, view, params) for c in seen) >= T_HP, f"trial {i}: not merged"
        pieces = cluster_splits(frame, robot, params)
        _white_box_and_not_the_lookalike(pieces, view, params, draw, layout, 0.02)


def test_touching_trials_that_stopped_now_succeed(clumsy_tree_0) -> None:
    """One clumsy demonstration recorded and compiled; touching trials that stopped with
    ``no_contingent_smc`` run end to end and put the white box in the orange box."""
    rows = la.run_trials(clumsy_tree_0, 0, (*TOUCHING[1:], *ANGLED, SIDE), 1, TWIN_THRESHOLD)
    for row in rows:
        assert row["success"], f"trial {row['trial']}: {row['outcome']}: {row['reason']}"


def test_two_bars_at_an_angle_fall_apart_by_direction() -> None:
    """Two 14 x 4 cm bars meeting end to end at 50 degrees (an L, as the look-alike family
    draws them), their tops sampled every 4 mm: the local direction divides them."""
    from smccli.perception.splits import MIN_DIRECTION_STEP, local_direction, otsu_split

    u, v = np.meshgrid(np.arange(0.0, 0.14, 0.004), np.arange(-0.02, 0.02, 0.004))
    bar = np.c_[u.ravel(), v.ravel()]
    turn = np.radians(50)
    rot = np.array([[np.cos(turn), np.sin(turn)], [-np.sin(turn), np.cos(turn)]])
    other = bar @ rot + [0.14 + 0.02 * np.sin(turn), 0.0]
    xy = np.r_[bar, other]
    mask = otsu_split(local_direction(np.c_[xy, np.full(len(xy), 0.05)]), MIN_DIRECTION_STEP)
    assert mask is not None
    # Each bar's middle on its own side (a bar's last 2 cm look across it: pieces there
    # are small, and the taught perception judges every piece).
    middle = (u.ravel() > 0.02) & (u.ravel() < 0.12)
    first, second = mask[: len(bar)][middle].mean(), mask[len(bar) :][middle].mean()
    assert min(first, 1 - first) < 0.05 and min(second, 1 - second) < 0.05
    assert abs(first - second) > 0.9


def test_the_end_of_a_piece_too_long_is_the_white_box(clumsy_tree_2, tmp_path) -> None:
    """Where neither a cluster nor a piece of one is within T_hP of the demonstration's
    white box, the end of a piece as long as the taught box is, on the white box; no end
    of the look-alike passes for it."""

    taught = _taught(clumsy_tree_2)
    params = scene_perception(la.learning_scene())
    for i in ENDS:
        draw = la.draw_trial(la.learning_scene(), 2, i)
        layout, frame, robot = _trial_view(draw, tmp_path / str(i))
        seen = clusters_from_frame(frame, robot, params) + cluster_splits(frame, robot, params)
        assert min(d_cluster(c, taught, _exact(params)) for c in seen) >= T_HP, f"trial {i}"
        ends = cluster_windows(frame, robot, params, sizes=(_size(taught),))
        _white_box_and_not_the_lookalike(ends, taught, params, draw, layout, 0.03)


def test_the_side_of_a_piece_too_wide_is_the_white_box(clumsy_tree_0, tmp_path) -> None:
    """Where a look-alike along the white box's side makes every piece holding it too wide,
    the window of the taught width at its far side is the white box; none on the
    look-alike passes for it."""
    taught = _taught(clumsy_tree_0)
    params = scene_perception(la.learning_scene())
    draw = la.draw_trial(la.learning_scene(), 0, SIDE)
    layout, frame, robot = _trial_view(draw, tmp_path / "side")
    seen = clusters_from_frame(frame, robot, params) + cluster_splits(frame, robot, params)
    assert min(d_cluster(c, taught, _exact(params)) for c in seen) >= T_HP
    found = cluster_windows(frame, robot, params, sizes=(_size(taught),), ends_only=False)
    _white_box_and_not_the_lookalike(found, taught, params, draw, layout, 0.03)


def test_a_piece_cut_from_its_cluster_is_as_bright_as_the_sides_beneath_it(tmp_path) -> None:
    """Development seed 8's 181: a 0.40 grey look-alike 2 cm from the white box, each cut
    by brightness into its clipped top and the rest. Every piece of the look-alike reads
    as dark as its sides, every piece of the white box as bright as its own: none is of
    unknown brightness (the look-alike's top had been, and was grasped)."""
    draw = la.draw_trial(la.learning_scene(), 8, 181)
    layout, frame, robot = _trial_view(draw, tmp_path / "t")
    pieces = cluster_splits(frame, robot, scene_perception(la.learning_scene()))
    on_lookalike = [c.brightness for c in pieces if _off(c, draw.pose) < 0.01]
    on_white = [c.brightness for c in pieces if _off(c, layout[la.TARGET]) < 0.01]
    assert len(on_lookalike) >= 2 and max(on_lookalike) < 0.6, on_lookalike
    assert len(on_white) >= 2 and min(on_white) > 0.9, on_white


def test_a_piece_too_short_grows_into_its_cluster() -> None:
    """A 14 x 4 cm bar whose last 3 cm went to the piece of a bar across its end (an L): a
    window of the taught size from the piece's far end, on the cluster's points, is the
    whole bar and nothing of the other."""
    u, v = np.meshgrid(np.arange(0.0, 0.14, 0.004), np.arange(-0.018, 0.02, 0.004))
    bar = np.c_[u.ravel(), v.ravel()]
    across = np.c_[v.ravel() + 0.162, u.ravel() - 0.07]  # its side against the bar's end
    xy = np.r_[bar, across]
    part = np.flatnonzero(bar[:, 0] < 0.11)
    found = windows(xy, part, 0.0, np.array([0.108, 0.036]), ((0.14, 0.038),))
    whole_bar = set(range(len(bar)))
    assert any(set(w.tolist()) == whole_bar for w in found)


def test_a_lookalike_against_the_white_box_s_end_no_longer_stops_the_robot(
    clumsy_tree_2,
) -> None:
    """Development seed 2's trial that stopped with the look-alike against the white box's
    end runs end to end and puts the white box in the orange box."""
    (row,) = la.run_trials(clumsy_tree_2, 2, ENDS[-1:], 1, TWIN_THRESHOLD)
    assert row["gap_m"] < 0.002
    assert row["success"], f"trial {row['trial']}: {row['outcome']}: {row['reason']}"
