"""Goal frames: each frame's storing and mapping back are inverse, whatever the poses."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from smccli.learn import frames
from smccli.perception import Cluster
from smccli.world import geometry as g

# Per test, not a profile: a profile loaded here would change every other module's.
EXAMPLES = settings(max_examples=200, derandomize=True, deadline=None)

coord = st.floats(-3.0, 3.0, allow_nan=False)
angle = st.floats(-math.pi, math.pi, allow_nan=False)
planar = st.tuples(coord, coord, angle).map(np.array)
poi = st.tuples(coord, coord, coord, angle).map(np.array)


def cluster(x: float, y: float, yaw: float, period: float) -> Cluster:
    return Cluster(
        centroid=np.array([x, y, 0.05]),
        yaw=yaw,
        yaw_period=period,
        extents=np.array([0.1, 0.05, 0.1]),
        histogram=np.full(8, 1 / 8),
        n_points=500,
    )


@EXAMPLES
@given(poi, coord, coord, angle)
def test_object_frame_round_trip(goal: np.ndarray, x: float, y: float, yaw: float) -> None:
    """No symmetry, no flip: the goal comes back where it was, its yaw the turn nearest."""
    c = cluster(x, y, yaw, g.TWO_PI)
    back = frames.goal_from_object(
        frames.goal_in_object(goal, c), c, near_yaw=float(goal[3]), flip=False
    )
    np.testing.assert_allclose(back, goal, atol=1e-9)


@EXAMPLES
@given(poi, coord, coord, angle, angle)
def test_an_object_that_moved_carries_its_goal(
    goal: np.ndarray, x: float, y: float, yaw: float, turn: float
) -> None:
    """Moving the object moves the goal rigidly with it (eq. 38-39)."""
    c = cluster(0.2, -0.1, yaw, g.TWO_PI)
    moved = cluster(x, y, yaw + turn, g.TWO_PI)
    motion = g.compose(np.array([x, y, yaw + turn]), g.inverse(np.array([0.2, -0.1, yaw])))
    want = g.compose(motion, goal)
    got = frames.goal_from_object(
        frames.goal_in_object(goal, c), moved, near_yaw=float(want[3]), flip=False
    )
    np.testing.assert_allclose(got[:3], want[:3], atol=1e-9)
    assert abs(g.wrap(got[3] - want[3])) < 1e-9


@EXAMPLES
@given(planar, planar)
def test_scan_frame_round_trip(goal: np.ndarray, lidar: np.ndarray) -> None:
    rel = frames.goal_in_scan(goal, lidar)
    back = frames.goal_at_scan_pose(rel, lidar)
    np.testing.assert_allclose(back[:2], goal[:2], atol=1e-9)
    assert abs(g.wrap(back[2] - goal[2])) < 1e-9
    # The same scan seen from the same place: the alignment is the identity.
    mapped = frames.goal_from_scan(rel, np.eye(3), lidar)
    np.testing.assert_allclose(mapped[:2], back[:2], atol=1e-12)
    assert abs(g.wrap(mapped[2] - back[2])) < 1e-12


@EXAMPLES
@given(poi, poi)
def test_hand_frame_round_trip(goal: np.ndarray, hand: np.ndarray) -> None:
    rel = frames.goal_in_hand(hand, goal)
    np.testing.assert_allclose(g.compose(frames.hand_frame(hand, None, None), rel), goal, atol=1e-9)
