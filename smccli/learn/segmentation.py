"""Temporal saliency (paper 3.1): cut a demonstration into fragments [t_{j-1}, t_j].

Boundaries come from the operator's saliency marks (``markers``), from an automatic
detector on the trace (``auto``: gripper command edges, weight steps, long pauses found
as change points of the POI speed), or both. With ``both``, marks are fixed boundaries and
automatic cuts only fill unmarked stretches longer than ``auto_gap``.

A mark is snapped to the *settled end* of a gripper or weight edge within ``snap_window``:
a person presses the button a little early or late, and the decision point should be
where the world has stopped changing (fingers closed, scale reading steady), since that
is where perceptions are read and where replay will decide.

Last, each fragment's idle head and tail are trimmed (:mod:`smccli.learn.trim`, settings
``idle``): it then starts where its commands start moving and ends where they stop, so its
DMP replays the motion and not the operator's waiting. Trimmed fragments no longer tile
the log: a fragment starts at or after the previous one's end.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from enum import Enum
from typing import TYPE_CHECKING

import numpy as np

from smccli.errors import LogError
from smccli.learn.trim import IdleParams, idle_centres, trim_interval
from smccli.world.sensors import PoiCommand

if TYPE_CHECKING:
    from smccli.logs.log import Log


class SegmentMode(str, Enum):
    """Where fragment boundaries come from."""

    markers = "markers"
    auto = "auto"
    both = "both"


@dataclass(frozen=True, slots=True)
class Fragment:
    """One fragment of a demonstration (an SMT fragment T^{i,j})."""

    t0: float
    """Start t_{j-1} [s]: the decision point where perceptions are read."""
    t1: float
    """End t_j [s]: where the POI decides which perception is salient."""
    cause: str
    """What made the end boundary: ``operator``, ``gripper``, ``weight``, ``pause`` or ``end``."""
    idle_head: float = 0.0
    """Idle time trimmed before ``t0`` (the untrimmed fragment started that much earlier) [s]."""
    idle_tail: float = 0.0
    """Idle time trimmed after ``t1`` (the untrimmed boundary is ``t1 + idle_tail``) [s]."""


@dataclass(frozen=True, slots=True)
class Trace:
    """The signals temporal saliency looks at, sampled from a log."""

    t_cmd: np.ndarray
    """Command times, shape (N,) [s]."""
    gripper_cmd: np.ndarray
    """Gripper opening command, shape (N,) in [0, 1]."""
    target: np.ndarray
    """Commanded POI, shape (N, 4) [m, m, m, rad]."""
    t_fingers: np.ndarray
    """Finger joint sample times, shape (M,) [s]."""
    finger_speed: np.ndarray
    """Largest finger joint speed, shape (M,) [m/s or rad/s]."""
    t_weight: np.ndarray
    """Scale sample times, shape (K,) [s]; empty without a scale."""
    weight: np.ndarray
    """Scale reading, shape (K,) [kg]."""
    marks: tuple[float, ...]
    """Operator saliency mark times [s]."""
    t_end: float
    """End of the log [s]."""
    base: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """A mobile manipulator's commanded base ``[x, y, yaw]``, shape (N, 3) [m, rad]; empty
    (0, 3) for other robots."""


def _settle_time(
    t: np.ndarray, speed: np.ndarray, t_edge: float, thr: float, hold: float, cap: float
) -> float:
    """First time after ``t_edge`` from which ``speed`` stays below ``thr`` for ``hold`` s."""
    if len(t) == 0:
        return t_edge
    sel = (t >= t_edge) & (t <= t_edge + cap)
    ts, vs = t[sel], speed[sel]
    quiet_since: float | None = None
    for ti, vi in zip(ts, vs, strict=True):
        if vi < thr:
            if quiet_since is None:
                quiet_since = float(ti)
            if ti - quiet_since >= hold:
                return quiet_since
        else:
            quiet_since = None
    return min(t_edge + cap, float(ts[-1])) if len(ts) else t_edge


def gripper_edges(trace: Trace) -> list[float]:
    """Settled ends of gripper command changes [s]."""
    g = trace.gripper_cmd
    if len(g) < 2:
        return []
    idx = np.nonzero(np.abs(np.diff(g)) > 0.25)[0] + 1
    ends = []
    for i in idx:
        t_edge = float(trace.t_cmd[i])
        ends.append(_settle_time(trace.t_fingers, trace.finger_speed, t_edge, 0.01, 0.15, 2.0))
    return ends


def weight_edges(trace: Trace, step: float = 0.02) -> list[float]:
    """Settled ends of steps in the scale reading larger than ``step`` [kg]."""
    if len(trace.weight) < 5:
        return []
    t, w = trace.t_weight, trace.weight
    # Rate over a 0.2 s window so that sensor noise does not look like a step.
    dt = max(float(np.median(np.diff(t))), 1e-3)
    k = max(1, int(round(0.2 / dt)))
    rate = np.zeros_like(w)
    rate[k:] = np.abs(w[k:] - w[:-k]) / (k * dt)
    ends: list[float] = []
    i = k
    while i < len(w):
        if abs(w[i] - w[i - k]) > step:
            t_end = _settle_time(t, rate, float(t[i]), step / 0.5, 0.2, 3.0)
            ends.append(t_end)
            j = int(np.searchsorted(t, t_end + 0.2))
            i = max(j, i + 1)
        else:
            i += 1
    return ends


def pause_cuts(trace: Trace, t0: float, t1: float, min_pause: float = 0.4) -> list[float]:
    """Change points of the POI command speed in [t0, t1]: the ends of long pauses [s].

    Uses ruptures (PELT) on the speed profile; keeps a cut only where the robot really
    stood still for ``min_pause`` before moving again.
    """
    import ruptures

    sel = (trace.t_cmd >= t0) & (trace.t_cmd <= t1)
    t, x = trace.t_cmd[sel], trace.target[sel, :3]
    if len(t) < 20:
        return []
    speed = np.linalg.norm(np.gradient(x, t, axis=0), axis=1)
    algo = ruptures.Pelt(model="l2", min_size=int(0.3 / max(np.median(np.diff(t)), 1e-3))).fit(
        speed.reshape(-1, 1)
    )
    cuts: list[float] = []
    for bkp in algo.predict(pen=float(np.var(speed) * 20 + 1e-6))[:-1]:
        before = speed[max(0, bkp - int(min_pause / np.median(np.diff(t)))) : bkp]
        if (
            len(before)
            and float(np.max(before)) < 0.01
            and speed[min(bkp + 5, len(speed) - 1)] > 0.01
        ):
            cuts.append(float(t[bkp]))
    return cuts


def _one_event_per_window(edges: list[tuple[float, str]], window: float) -> list[tuple[float, str]]:
    """Edges closer than ``window`` are one event (a release *is* the scale's step): keep
    the last, where everything has settled, named after the first (its cause)."""
    out: list[tuple[float, str]] = []
    for t, cause in edges:
        if out and t - out[-1][0] <= window:
            out[-1] = (t, out[-1][1])
        else:
            out.append((t, cause))
    return out


def segment(
    trace: Trace,
    mode: SegmentMode,
    *,
    snap_window: float,
    min_fragment: float,
    auto_gap: float,
    idle: IdleParams | None = None,
) -> list[Fragment]:
    """Fragments of a demonstration, in time order (paper 3.1).

    The log's start opens the first fragment; each boundary closes one. Boundaries closer
    than ``min_fragment`` collapse into the later one. No boundary at all: one fragment.
    Then each fragment's idle head and tail are trimmed (:func:`trim_idle`) with ``idle``
    (default :class:`~smccli.learn.trim.IdleParams`; ``trim=False`` keeps them).
    """
    return trim_idle(
        trace,
        _boundaries(
            trace, mode, snap_window=snap_window, min_fragment=min_fragment, auto_gap=auto_gap
        ),
        IdleParams() if idle is None else idle,
        min_fragment,
    )


def trim_idle(
    trace: Trace, fragments: list[Fragment], idle: IdleParams, min_fragment: float
) -> list[Fragment]:
    """``fragments`` with their idle heads and tails cut off (:mod:`smccli.learn.trim`),
    each kept at least ``min_fragment`` long; unchanged when ``idle.trim`` is False. A
    mobile manipulator's (``trace.base``) keep their heads: their start is where its slow
    sensors recorded the decision point."""
    if not idle.trim or len(trace.t_cmd) < 3:
        return fragments
    t = trace.t_cmd
    base = trace.base if len(trace.base) == len(t) else None
    # A mobile manipulator's scenes run a slow camera and lidar that record at the
    # decision points (scene camera ``at_marks``), where compile perceives: its fragments
    # keep their start and lose only their idle tails.
    heads = base is None
    out = []
    for f in fragments:
        # Windows end at the fragment's ends: the next fragment's first move must not make
        # this one's idle tail look busy.
        sel = np.nonzero((t >= f.t0 - 1e-9) & (t <= f.t1 + 1e-9))[0]
        still = idle_centres(
            t[sel],
            trace.target[sel],
            trace.gripper_cmd[sel],
            None if base is None else base[sel],
            idle,
        )
        m0, m1 = trim_interval(t[sel], still, f.t0, f.t1, idle, min_fragment)
        m0 = m0 if heads else f.t0
        out.append(replace(f, t0=m0, t1=m1, idle_head=m0 - f.t0, idle_tail=f.t1 - m1))
    return out


def _boundaries(
    trace: Trace, mode: SegmentMode, *, snap_window: float, min_fragment: float, auto_gap: float
) -> list[Fragment]:
    """The untrimmed fragments of :func:`segment`: they tile the log from 0 to the last
    boundary."""
    edges = _one_event_per_window(
        sorted(
            [(t, "gripper") for t in gripper_edges(trace)]
            + [(t, "weight") for t in weight_edges(trace)]
        ),
        snap_window,
    )
    bounds: list[tuple[float, str]] = []
    if mode in (SegmentMode.markers, SegmentMode.both):
        for m in trace.marks:
            near = [(abs(t - m), t, c) for t, c in edges if abs(t - m) <= snap_window]
            bounds.append((min(near)[1], "operator") if near else (m, "operator"))
    if mode is SegmentMode.auto:
        bounds.extend(edges)
    if mode is SegmentMode.both:
        fixed = sorted({0.0, trace.t_end, *(b for b, _ in bounds)})
        for a, b in zip(fixed[:-1], fixed[1:], strict=True):
            if b - a > auto_gap:
                inner = [(t, c) for t, c in edges if a + min_fragment < t < b - min_fragment]
                bounds.extend(inner)
    if mode in (SegmentMode.auto, SegmentMode.both):
        fixed = sorted({0.0, trace.t_end, *(b for b, _ in bounds)})
        for a, b in zip(fixed[:-1], fixed[1:], strict=True):
            if b - a > auto_gap:
                bounds.extend((t, "pause") for t in pause_cuts(trace, a, b))
    bounds.sort()
    if not bounds:
        # No salient moment at all: the whole log is one fragment (the caller warns).
        return [Fragment(t0=0.0, t1=trace.t_end, cause="end")]
    # Boundaries are fragment *ends* (paper 4.1: two marks, two fragments); what follows
    # the last one is the operator leaving the scene, not part of the task.
    fragments: list[Fragment] = []
    start = 0.0
    for t, cause in bounds:
        if t - start >= min_fragment:
            fragments.append(Fragment(t0=start, t1=t, cause=cause))
            start = t
        elif fragments:
            # Two boundaries closer than min_fragment (a double press): keep the later one.
            fragments[-1] = Fragment(t0=fragments[-1].t0, t1=t, cause=cause)
            start = t
        # else: a boundary right at the start (a press as recording began) cuts nothing.
    if not fragments:
        return [Fragment(t0=0.0, t1=trace.t_end, cause="end")]
    return fragments


def trace_from_commands(
    commands: list[PoiCommand],
    t_fingers: np.ndarray,
    finger_speed: np.ndarray,
    t_weight: np.ndarray,
    weight: np.ndarray,
    marks: tuple[float, ...],
    t_end: float,
) -> Trace:
    """Assemble a :class:`Trace` from decoded log messages."""
    t_cmd = np.array([c.t for c in commands], dtype=float)
    bases = [c.base for c in commands]
    has_base = bool(bases) and all(b is not None for b in bases)
    return Trace(
        t_cmd=t_cmd,
        gripper_cmd=np.array([c.gripper for c in commands], dtype=float),
        target=np.array([c.target for c in commands], dtype=float).reshape(-1, 4),
        t_fingers=np.asarray(t_fingers, dtype=float),
        finger_speed=np.asarray(finger_speed, dtype=float),
        t_weight=np.asarray(t_weight, dtype=float),
        weight=np.asarray(weight, dtype=float),
        marks=tuple(sorted(marks)),
        t_end=float(t_end),
        base=np.array(bases, dtype=float).reshape(-1, 3) if has_base else np.zeros((0, 3)),
    )


def fragment_commands(log: Log, frag: Fragment) -> list[PoiCommand]:
    """The operator's commands within ``frag``; LogError when fewer than 3 (no DMP fits)."""
    cmds = [c for c in log.commands if frag.t0 - 1e-6 <= c.t <= frag.t1 + 1e-6]
    if len(cmds) < 3:
        raise LogError(
            f"{log.path.name}: fragment {frag.t0:.2f}-{frag.t1:.2f} s holds fewer than 3 "
            "operator commands"
        )
    return cmds
