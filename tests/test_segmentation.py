"""Temporal saliency (paper 3.1): marks, snapping to gripper/weight edges, auto cuts."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from smccli.learn.segmentation import SegmentMode, Trace, segment
from smccli.learn.trim import IdleParams

DT = 0.01


def make_trace(t_end=10.0, closes=(), opens=(), weight_steps=(), marks=(), pauses=()):
    """A synthetic trace: gripper commands switching at ``closes``/``opens``, fingers moving
    for 0.4 s after each switch, weight steps settling over 0.3 s, and the POI moving
    except during ``pauses`` (start, end) windows."""
    t = np.arange(0.0, t_end, DT)
    grip = np.ones_like(t)
    for tc in closes:
        grip[t >= tc] = 0.0
        for to in opens:
            if to > tc:
                grip[t >= to] = 1.0
    speed = np.zeros_like(t)
    for te in (*closes, *opens):
        speed[(t >= te) & (t < te + 0.4)] = 0.05
    weight = np.zeros_like(t)
    for ts, dw in weight_steps:
        weight += dw * np.clip((t - ts) / 0.3, 0.0, 1.0)
    target = np.zeros((len(t), 4))
    moving = np.ones_like(t, dtype=bool)
    for a, b in pauses:
        moving[(t >= a) & (t < b)] = False
    target[:, 0] = np.cumsum(np.where(moving, 0.1 * DT, 0.0))
    return Trace(
        t_cmd=t,
        gripper_cmd=grip,
        target=target,
        t_fingers=t,
        finger_speed=speed,
        t_weight=t,
        weight=weight,
        marks=tuple(marks),
        t_end=float(t[-1]),
    )


def seg(trace, mode=SegmentMode.markers):
    return segment(trace, mode, snap_window=0.5, min_fragment=0.3, auto_gap=4.0)


def test_marks_end_fragments_and_the_tail_is_dropped():
    frags = seg(make_trace(marks=(3.0, 6.0)))
    assert [(f.t0, f.t1) for f in frags] == [(0.0, 3.0), (3.0, 6.0)]
    assert all(f.cause == "operator" for f in frags)


def test_a_mark_snaps_to_the_settled_end_of_a_nearby_gripper_edge():
    # Gripper closes at 2.0, fingers stop at 2.4; the operator pressed at 2.7.
    frags = seg(make_trace(closes=(2.0,), marks=(2.7,)))
    assert abs(frags[0].t1 - 2.4) < 0.02


def test_a_mark_far_from_any_edge_stays_put():
    frags = seg(make_trace(closes=(2.0,), marks=(5.0,)))
    assert frags[0].t1 == 5.0


def test_a_mark_snaps_to_a_weight_step():
    frags = seg(make_trace(weight_steps=((4.0, 0.5),), marks=(4.1,)))
    assert 4.2 < frags[0].t1 < 4.6


def test_no_boundary_gives_one_fragment():
    frags = seg(make_trace(t_end=5.0))
    assert len(frags) == 1 and frags[0].t0 == 0.0


def test_auto_cuts_at_gripper_and_weight_edges():
    frags = seg(
        make_trace(closes=(2.0,), opens=(5.0,), weight_steps=((7.0, 0.3),)), SegmentMode.auto
    )
    assert [f.cause for f in frags] == ["gripper", "gripper", "weight"]


def test_both_fills_only_long_unmarked_stretches():
    # Marked at 2 s; a gripper edge at 8 s in a 10 s unmarked stretch gets an auto cut,
    # the one at 1 s (inside a marked stretch shorter than auto_gap) does not.
    tr = make_trace(t_end=14.0, closes=(1.0,), opens=(8.0,), marks=(2.0, 13.0))
    causes = [f.cause for f in seg(tr, SegmentMode.both)]
    assert causes.count("operator") == 2 and "gripper" in causes
    assert all(abs(f.t1 - 1.4) > 0.05 for f in seg(tr, SegmentMode.both))


def test_double_press_collapses():
    frags = seg(make_trace(marks=(3.0, 3.1, 6.0)))
    assert [round(f.t1, 2) for f in frags] == [3.1, 6.0]


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(0.05, 11.9), max_size=8),
    st.sampled_from(list(SegmentMode)),
    st.lists(st.tuples(st.floats(0.0, 11.0), st.floats(0.2, 3.0)), max_size=3),
)
def test_fragments_tile_time_in_order(marks, mode, pauses):
    """Invariants: untrimmed fragments are contiguous, ordered, each at least min_fragment
    long, inside the log; trimmed ones lie inside their untrimmed tile, in order, still at
    least min_fragment long (idle heads and tails are cut, never motion)."""
    tr = make_trace(
        t_end=12.0,
        closes=(2.0,),
        opens=(6.0,),
        marks=sorted(marks),
        pauses=[(a, a + d) for a, d in pauses],
    )
    tiles = segment(
        tr, mode, snap_window=0.5, min_fragment=0.3, auto_gap=4.0, idle=IdleParams(trim=False)
    )
    assert tiles and tiles[0].t0 == 0.0
    for a, b in zip(tiles, tiles[1:], strict=False):
        assert a.t1 == b.t0
    for f in tiles:
        assert f.t1 - f.t0 >= 0.3 - 1e-9 or len(tiles) == 1
        assert 0.0 <= f.t0 < f.t1 <= tr.t_end + 1e-9
    frags = seg(tr, mode)
    assert len(frags) == len(tiles)
    for f, tile in zip(frags, tiles, strict=True):
        assert tile.t0 <= f.t0 < f.t1 <= tile.t1
        assert f.t0 - tile.t0 == pytest.approx(f.idle_head)
        assert tile.t1 - f.t1 == pytest.approx(f.idle_tail)
        assert f.t1 - f.t0 >= min(0.3, tile.t1 - tile.t0) - 1e-9


def test_idle_head_and_tail_are_trimmed_from_a_pause():
    """A fragment that starts with a 2 s pause and ends with a 1.5 s one loses both."""
    tr = make_trace(t_end=10.0, pauses=[(0.0, 2.0), (4.5, 6.0)], marks=(6.0,))
    (f,) = seg(tr)
    assert 1.7 <= f.t0 <= 2.0 and 4.5 <= f.t1 <= 4.8
    (g,) = segment(
        tr,
        SegmentMode.markers,
        snap_window=0.5,
        min_fragment=0.3,
        auto_gap=4.0,
        idle=IdleParams(trim=False),
    )
    assert (g.t0, g.t1) == (0.0, 6.0)


def test_a_mobile_manipulators_fragments_keep_their_start():
    """Its slow camera and lidar record at the decision points: only the tail is trimmed."""
    tr = make_trace(t_end=10.0, pauses=[(0.0, 2.0), (4.5, 6.0)], marks=(6.0,))
    tr = Trace(
        **{**{k: getattr(tr, k) for k in Trace.__slots__}, "base": np.zeros((len(tr.t_cmd), 3))}
    )
    (f,) = seg(tr)
    assert f.t0 == 0.0 and 4.5 <= f.t1 <= 4.8
