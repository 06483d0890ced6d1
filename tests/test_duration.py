"""Idle trimming and replay speed (paper 6: executions shorter than the demonstration).

Durations compared here are simulated time, never wall time.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from smccli.bench.duration import pausing_script
from smccli.errors import SmcError
from smccli.execute.campaign import run_campaign
from smccli.execute.episode import run_episode
from smccli.execute.executor import at_speed, check_speed, speed_limit
from smccli.learn.compile import compile_logs, fragments
from smccli.learn.params import SmcParams, params_from_dict, params_to_dict
from smccli.learn.segmentation import SegmentMode, Trace, segment
from smccli.learn.tree import load_tree
from smccli.learn.trim import IdleParams, active_times, idle_centres
from smccli.logs.reader import read_log

DT = 0.01


def _trace(moves, t_end, *, grip_at=None, marks=(), tremor=0.0005, steps=False, seed=0):
    """A synthetic command trace: min-jerk ``moves`` ``(t_start, t_stop, dx)`` along x
    (or 1 cm jumps every 0.2 s with ``steps``, like the keyboard), AR(1) tremor as the
    scripted operator's, the gripper closing at ``grip_at``."""
    t = np.arange(0.0, t_end + DT / 2, DT)
    x = np.zeros_like(t)
    for a, b, dx in moves:
        s = np.clip((t - a) / (b - a), 0.0, 1.0)
        if steps:
            x += dx * np.floor(s * round(abs(dx) / 0.01) + 1e-9) / round(abs(dx) / 0.01)
        else:
            x += dx * s**3 * (10 - 15 * s + 6 * s**2)
    target = np.zeros((len(t), 4))
    target[:, 0] = 0.4 + x
    target[:, 2] = 0.9
    rng, a = np.random.default_rng(seed), np.exp(-DT / 0.15)
    noise = np.zeros(3)
    for i in range(len(t)):
        noise = a * noise + np.sqrt(1 - a * a) * tremor * rng.standard_normal(3)
        target[i, :3] += noise
    grip = np.ones_like(t) if grip_at is None else np.where(t >= grip_at, 0.0, 1.0)
    return Trace(
        t_cmd=t,
        gripper_cmd=grip,
        target=target,
        t_fingers=t,
        finger_speed=np.zeros_like(t),
        t_weight=np.zeros(0),
        weight=np.zeros(0),
        marks=tuple(marks),
        t_end=float(t[-1]),
    )


def _seg(trace, idle=None):
    kw = dict(snap_window=0.5, min_fragment=0.3, auto_gap=4.0)
    return segment(trace, SegmentMode.markers, idle=idle, **kw)


def test_trimming_removes_a_known_idle_head_and_tail():
    # Idle 2.0 s, move 1.5 s, idle 1.0 s, close, idle 1.2 s, mark at 5.7 s.
    tr = _trace([(2.0, 3.5, 0.2)], 7.0, grip_at=4.5, marks=(5.7,))
    (f,) = _seg(tr)
    half = IdleParams().window / 2  # a window's half of rest may stay at each end
    assert 2.0 - half - 0.02 <= f.t0 <= 2.0
    assert f.t1 == pytest.approx(4.5, abs=DT)  # ends on the gripper switch
    assert f.idle_head == pytest.approx(f.t0) and f.idle_tail == pytest.approx(5.7 - f.t1)
    (g,) = _seg(tr, IdleParams(trim=False))
    assert (g.t0, g.t1) == (0.0, 5.7)


def test_trimming_keeps_the_whole_approach_and_a_keyboard_staircase():
    # A slow approach must not lose its last millimetres (that would move the goal).
    tr = _trace([(1.0, 4.0, 0.3)], 6.0, marks=(6.0,), tremor=0.0)
    (f,) = _seg(tr)
    end = int(round(f.t1 / DT))
    assert abs(tr.target[end, 0] - 0.7) < 0.001
    # Keyboard: 1 cm jumps from 1.0 to 2.0 s, then nothing until the mark at 4 s.
    kb = _trace([(1.0, 2.0, 0.05)], 4.0, marks=(4.0,), steps=True, tremor=0.0)
    (k,) = _seg(kb)
    assert 0.7 <= k.t0 <= 1.0 and 2.0 <= k.t1 <= 2.3


def test_a_fragment_that_only_closes_the_gripper_stays_compilable():
    tr = _trace([], 3.0, grip_at=2.0, marks=(3.0,), tremor=0.0)
    (f,) = _seg(tr)
    assert f.t1 == pytest.approx(2.0, abs=DT) and f.t1 - f.t0 >= 0.3 - 1e-9


def test_active_times_cut_pauses_inside_a_fragment():
    tr = _trace([(0.0, 1.0, 0.1), (3.0, 4.0, 0.1)], 4.0)
    p = IdleParams()
    clock = active_times(tr.t_cmd, idle_centres(tr.t_cmd, tr.target, tr.gripper_cmd, None, p), p)
    assert np.all(np.diff(clock) >= 0)
    # 4 s with a 2 s pause: two 1 s moves (their last and first millimetres, slower than
    # the threshold, go with the pause) and a 0.1 s rest.
    assert 1.6 < clock[-1] < 2.2


def test_trees_from_before_trimming_load_untrimmed():
    doc = params_to_dict(SmcParams())
    assert doc["idle"]["trim"] is True
    old = {k: v for k, v in doc.items() if k != "idle"}
    params = params_from_dict(SmcParams, old)
    assert params.idle.trim is False
    assert "idle" not in params_to_dict(params)  # so an old tree keeps its digest


# --- a pausing demonstration, recorded, compiled, replayed --------------------------------


@pytest.fixture(scope="module")
def pausing(tmp_path_factory) -> tuple[Path, Path, float]:
    """A short pausing bench_pick demo (waits of 1 s), its tree, and the demonstrated task
    duration (log start to the last untrimmed fragment end) [s]."""
    from smccli.record.session import RecordConfig, record

    d = tmp_path_factory.mktemp("pausing")
    script = d / "slow.yaml"
    script.write_text(pausing_script(wait=1.0, speed=0.15))
    log = d / "slow.mcap"
    record(RecordConfig(scene="bench_pick", script=script, seed=3, output=log, randomize=True))
    tree = d / "tree.json"
    compile_logs([log], tree)
    frags = fragments(read_log(log), SmcParams())
    assert sum(f.idle_head + f.idle_tail for f in frags) > 3.0  # the waits were trimmed
    return log, tree, frags[-1].t1 + frags[-1].idle_tail


def test_trees_from_before_squeezing_load_unsqueezed():
    doc = params_to_dict(SmcParams())
    assert doc["idle"]["squeeze"] is True
    old = {**doc, "idle": {k: v for k, v in doc["idle"].items() if k != "squeeze"}}
    params = params_from_dict(SmcParams, old)
    assert params.idle.trim is True and params.idle.squeeze is False
    assert "squeeze" not in params_to_dict(params)["idle"]  # its digest stays


def test_waits_inside_fragments_are_cut_from_the_dmps(pausing, tmp_path):
    """The pausing demo waits 1 s between the moves of each fragment: its DMPs last the
    moves alone (each wait cut to IdleParams.keep), where without squeezing they last
    the whole trimmed fragment, waits included."""
    log, tree_path, _ = pausing
    tree = load_tree(tree_path)
    squeezed = sum(e.smc.action.dmp.duration for e in tree.edges)
    trimmed = sum(s.t1 - s.t0 for e in tree.edges for s in e.sources)
    plain = tmp_path / "plain.json"
    compile_logs([log], plain, overrides=["idle.squeeze=false"])
    unsqueezed = sum(e.smc.action.dmp.duration for e in load_tree(plain).edges)
    assert unsqueezed == pytest.approx(trimmed, abs=0.05)
    # Five waits of 1-1.33 s lie between moves inside the two fragments (5.3 s); the
    # windows' edges keep a little of each.
    assert squeezed < trimmed - 3.0, (squeezed, trimmed)


def test_a_pausing_demo_replays_faster_than_demonstrated(pausing):
    _, tree, demo = pausing
    r = run_episode(tree, seed=0)
    assert r.success, r.reason
    assert r.duration < demo
    assert r.duration < 0.9 * demo  # the waits are gone, not just shaved
    # ... those inside the fragments too: faster than the demonstrated motion itself.
    assert r.duration < 0.8 * r.demo_duration, (r.duration, r.demo_duration)


def test_a_small_campaign_of_the_pausing_tree_succeeds(pausing, tmp_path):
    _, tree, _ = pausing
    s = run_campaign(tree, trials=6, workers=2, report=tmp_path / "c.json")
    assert s["successes"] >= 5, s["failures"]
    assert json.loads((tmp_path / "c.json").read_text())["speed"] == 1.0


def test_speed_scales_every_dmp_and_is_bounded(pausing):
    _, tree_path, _ = pausing
    tree = load_tree(tree_path)
    limit, edge, peak = speed_limit(tree)
    assert limit >= 1.0 and edge is not None and peak > 0
    fast = at_speed(tree, 1.25)
    for a, b in zip(tree.edges, fast.edges, strict=True):
        assert b.smc.action.dmp.duration == pytest.approx(a.smc.action.dmp.duration / 1.25)
    check_speed(tree, min(limit, 1.25))
    with pytest.raises(SmcError, match="exceeds this tree's limit"):
        check_speed(tree, limit * 1.1)
    with pytest.raises(SmcError, match="positive"):
        check_speed(tree, 0.0)


def test_speed_beyond_the_bound_is_a_one_line_error(pausing, monkeypatch, capsys):
    from smccli.cli import main

    _, tree, _ = pausing
    monkeypatch.setattr(sys, "argv", ["smc", "replay", str(tree), "--speed", "50"])
    monkeypatch.setenv("COLUMNS", "250")
    with pytest.raises(SystemExit) as exit_:
        main()
    assert exit_.value.code == 2
    lines = [ln for ln in capsys.readouterr().err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and "--speed 50 exceeds" in lines[0], lines
