"""Replay speed (``smc replay --speed F``): every DMP runs F times faster, its tau divided by
F (:func:`at_speed`); the floors of a rollout's duration
(:data:`~smccli.execute.plan.MIN_DURATION`, the wrist's
:data:`~smccli.execute.plan.MAX_YAW_RATE`), the holds and the gripper's waits stay as they
are. The robot files give no velocity limits, so the bound is the POI speed the controller
tracks well, :data:`MAX_POI_SPEED`, against the fastest POI speed the tree's DMPs reach as
demonstrated (:func:`speed_limit`); :func:`check_speed` refuses a factor beyond it.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from smccli.errors import SmcError
from smccli.learn.dmp import Dmp, rollout
from smccli.learn.tree import Tree

MAX_POI_SPEED = 0.5
"""Fastest POI speed a rollout may ask for at ``--speed`` above 1 [m/s]: half the speed
where the arm's tracking breaks down (its POI lags its target by centimetres beyond
1.2 m/s), and within a base's force caps (docs/choices.md, "Idle time and replay
speed")."""


def peak_speed(dmp: Dmp) -> float:
    """Fastest POI speed of ``dmp`` rolled out as demonstrated (start, goal, duration),
    positions only [m/s]; 0 for a DMP without positions."""
    if dmp.n_pos == 0:
        return 0.0
    t, y = rollout(dmp)
    if len(t) < 2:
        return 0.0
    v = np.linalg.norm(np.diff(y[:, : dmp.n_pos], axis=0), axis=1) / np.diff(t)
    return float(np.max(v))


def _dmps(tree: Tree) -> list[tuple[str, Dmp]]:
    out = []
    for e in tree.edges:
        a = e.smc.action
        out.append((e.id, a.dmp))
        if a.base_dmp is not None:
            out.append((e.id, a.base_dmp))
    return out


def speed_limit(tree: Tree) -> tuple[float, str | None, float]:
    """The largest ``--speed`` for ``tree``: (factor, the edge whose DMP is fastest, its
    demonstrated peak speed [m/s]). The factor is at least 1 (the demonstrated speed was
    executed by the same controller) and infinite for a tree without moves."""
    worst, edge = 0.0, None
    for eid, dmp in _dmps(tree):
        v = peak_speed(dmp)
        if v > worst:
            worst, edge = v, eid
    if worst <= 0:
        return math.inf, None, 0.0
    return max(1.0, MAX_POI_SPEED / worst), edge, worst


def check_speed(tree: Tree, speed: float) -> None:
    """SmcError (one line, exit 2) unless ``0 < speed <= speed_limit(tree)``."""
    if not (math.isfinite(speed) and speed > 0):
        raise SmcError(f"--speed must be a positive number, got {speed:g}")
    if speed == 1.0:
        return
    limit, edge, v = speed_limit(tree)
    if speed > limit + 1e-9:
        raise SmcError(
            f"--speed {speed:g} exceeds this tree's limit {limit:.2f}: SMC {edge} peaks at "
            f"{v:.2f} m/s as demonstrated and the robot's POI is held to {MAX_POI_SPEED} m/s"
        )


def at_speed(tree: Tree, speed: float) -> Tree:
    """``tree`` with every DMP ``speed`` times faster (tau / speed); the same tree at 1."""
    if speed == 1.0:
        return tree
    if not speed > 0:
        raise ValueError(f"at_speed: expected speed > 0, got {speed}")

    def fast(d: Dmp) -> Dmp:
        return replace(d, duration=d.duration / speed)

    edges = []
    for e in tree.edges:
        a = e.smc.action
        a = replace(a, dmp=fast(a.dmp), base_dmp=None if a.base_dmp is None else fast(a.base_dmp))
        edges.append(replace(e, smc=replace(e.smc, action=a)))
    return replace(tree, edges=tuple(edges))
