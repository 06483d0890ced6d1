"""Idle time at the ends of fragments: fit each fragment's DMP on its motion only.

A person teleoperating pauses: before the first key press of a fragment, between the last
move and the gripper key, while the fingers close, before pressing the saliency button.
An untrimmed fragment's DMP replays all of it (a 31 s keyboard demonstration of bench_pick
replayed at 1.11 times its duration). The paper's executions are shorter than the
demonstration because that waiting is dropped (section 6); here it is dropped when
compiling, by moving a fragment's start past its idle head and its end back to its last
motion (:func:`trim_fragment`), so the fragment's DMP, gripper phase and duration all
describe the motion alone.

Idle is measured on the *commands* (POI target, gripper, a mobile manipulator's base
target), not on the robot: what the operator asked for. A sample is idle when the command
moved less than ``speed * window`` (and turned less than ``yaw_rate * window``) over the
``window`` centred on it, and the gripper command does not change there. The motion of a
fragment runs from the first to the last sample that is not idle: a centred window sees a
motion half a window early and a rest half a window late, so the span keeps at most half a
window of rest at each end and never cuts into a slow start or a slow approach (which
would move the goal). A gripper change is an instant: a fragment that ends with one ends
on the first command carrying the new opening (its switch is then at the end, phase 1, and
replay waits for the fingers itself).

Why moving the fragment's start keeps the decision point's meaning: perceptions are read at
the fragment's start, and during its idle head neither the robot nor (by the settled-edge
snapping of :mod:`smccli.learn.segmentation`) the scene changes, so they are read later on
the same scene. The fragment's end is where its POI stopped, so the salient perception
found there (eq. 22) is the same.

Pauses *inside* a fragment (a person waiting between the approach moves) are cut down to
``keep`` by re-timing the fragment's commands before its DMP and gripper phase are fitted
(:func:`active_times`, used by compile with ``squeeze``): the path is the same, its clock
runs only while the command moves. A hesitation shorter than the window never makes an
idle centre (the window sees the moves on both sides), so scripted demonstrations, whose
hesitations last at most 0.2 s, keep their clock.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["IdleParams", "active_times", "idle_centres", "trim_interval"]


@dataclass(frozen=True, slots=True)
class IdleParams:
    """When a fragment's command counts as idle (the thresholds of :mod:`smccli.learn.trim`)."""

    trim: bool = True
    """Trim idle heads and tails of fragments; False: fragments as segmented (trees
    compiled before trimming existed load with False)."""
    speed: float = 0.01
    """A window whose command moved less than this on average is idle [m/s]. The scripted
    operator's tremor (0.5 mm, 0.15 s) moves a resting command 2-5 mm/s over 0.5 s; a
    scripted move averages 150 mm/s; a keyboard press moves the target 1 cm, 20 mm/s over
    the window."""
    yaw_rate: float = 0.05
    """... and turned less than this on average [rad/s] (keyboard: 0.1 rad per press)."""
    window: float = 0.5
    """Window of the average speed, centred on each command [s]."""
    min_idle: float = 0.2
    """An idle head or tail shorter than this is kept [s]: a scripted demonstration's
    fragments (which start moving at once) stay as they were."""
    squeeze: bool = field(default=True, metadata={"legacy": False})
    """Cut each pause *inside* a fragment (an idle run of at least ``min_idle``) down to
    ``keep`` before its DMP and gripper phase are fitted (:func:`active_times`), so the
    robot replays the motions back to back; a tree without this key was compiled without
    (an arm's fragments; a mobile manipulator's keep their clock: its base and hand DMPs
    share one duration)."""
    keep: float = field(default=0.1, metadata={"omit_default": True})
    """What is left of a squeezed pause [s]: the command's standstill between two moves."""


def idle_centres(
    t: np.ndarray,
    target: np.ndarray,
    gripper: np.ndarray,
    base: np.ndarray | None,
    p: IdleParams,
) -> np.ndarray:
    """Which command samples are idle, shape (N,) bool.

    ``t`` (N,) [s]; ``target`` (N, 4) ``[x, y, z, yaw]`` [m, rad]; ``gripper`` (N,) in
    [0, 1]; ``base`` (N, 3) ``[x, y, yaw]`` or None / empty. Windows are clipped at the
    trace's ends (a shorter span, still divided by ``window``); pass one fragment's
    samples so that a neighbour's motion does not spill into its windows."""
    t = np.asarray(t, dtype=float)
    n = len(t)
    if n == 0:
        return np.zeros(0, dtype=bool)
    half = p.window / 2
    lo = np.searchsorted(t, t - half, side="left")
    hi = np.clip(np.searchsorted(t, t + half, side="right") - 1, 0, n - 1)
    pos = [np.asarray(target, dtype=float)[:, :3]]
    ang = [np.unwrap(np.asarray(target, dtype=float)[:, 3])]
    if base is not None and len(base) == n:
        b = np.asarray(base, dtype=float)
        pos.append(b[:, :2])
        ang.append(np.unwrap(b[:, 2]))
    idle = np.ones(n, dtype=bool)
    for x in pos:
        idle &= np.linalg.norm(x[hi] - x[lo], axis=1) < p.speed * p.window
    for a in ang:
        idle &= np.abs(a[hi] - a[lo]) < p.yaw_rate * p.window
    g = np.asarray(gripper, dtype=float)
    change = np.zeros(n, dtype=bool)
    change[1:] = np.abs(np.diff(g)) > 1e-3
    return idle & ~change


def trim_interval(
    t: np.ndarray,
    idle: np.ndarray,
    t0: float,
    t1: float,
    p: IdleParams,
    min_length: float,
) -> tuple[float, float]:
    """The motion ``[m0, m1]`` of the fragment ``[t0, t1]``: its idle head and tail cut off
    when each lasts at least ``p.min_idle`` [s].

    ``t`` (N,) and ``idle`` (N,) from :func:`idle_centres` (a gripper change is not idle).
    ``m0`` and ``m1`` are command times: the first and last centres of a window that saw
    a motion (a fragment that ends with a gripper change ends on its first new command,
    unless the POI still moved within half a window before). The result lasts at
    least ``min_length`` where the fragment does (extended back towards ``t0`` first, so
    an end-of-fragment gripper switch stays at the end), and ``t0 <= m0 < m1 <= t1``.
    """
    sel = np.nonzero((t >= t0 - 1e-9) & (t <= t1 + 1e-9))[0]
    moving = np.nonzero(~idle[sel])[0]
    if len(sel) < 3 or len(moving) == 0:
        return t0, t1  # nothing moves at all: nothing to tell motion from rest by
    ts = t[sel]
    # The first and last centres whose window saw a motion: the span keeps at most half a
    # window of rest at each end, and no part of a slow start or approach.
    # The start keeps the sample before the first motion: when that motion is a gripper
    # switch (weigh_sort's regrasp waits on the scale, then closes), the fragment must hold
    # the opening before it, or its event would read "none".
    m0, m1 = float(ts[max(moving[0] - 1, 0)]), float(ts[moving[-1]])
    if m0 - t0 < p.min_idle:
        m0 = t0
    if t1 - m1 < p.min_idle:
        m1 = t1
    # Keep the fragment long enough to compile (min_fragment), back towards t0 first.
    if m1 - m0 < min_length:
        m0 = max(t0, m1 - min_length)
        m1 = min(t1, max(m1, m0 + min_length))
    return float(m0), float(m1)


def active_times(t: np.ndarray, idle: np.ndarray, p: IdleParams, keep: float = 0.1) -> np.ndarray:
    """The command clock with the pauses inside a fragment cut down to ``keep`` [s]: times
    (N,) [s] from 0, non-decreasing. A pause is a run of idle centres, neither at the first
    nor at the last sample, lasting at least ``p.min_idle``; its command stands still from
    half a window before the run to half a window after it, and that stretch of the clock
    is shrunk. A DMP and a gripper phase computed on this clock replay the motions back to
    back. (Compile times fragments by the commands' own clock; see docs/choices.md.)"""
    t = np.asarray(t, dtype=float)
    if len(t) < 2:
        return t - (t[0] if len(t) else 0.0)
    dt = np.diff(t)
    scale = np.ones_like(dt)
    idle = np.asarray(idle, dtype=bool)
    n, i = len(idle), 0
    while i < n:
        if not idle[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and idle[j + 1]:
            j += 1
        if 0 < i and j < n - 1 and t[j] - t[i] >= p.min_idle:
            a = int(np.searchsorted(t, t[i] - p.window / 2))
            b = min(n - 1, int(np.searchsorted(t, t[j] + p.window / 2)))
            still = t[b] - t[a]
            if still > keep:
                scale[a:b] = keep / still
        i = j + 1
    return np.r_[0.0, np.cumsum(dt * scale)]
