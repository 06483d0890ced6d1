"""Where a trial's time goes, in whatever smc checkout ``PYTHONPATH`` names.

Run by :mod:`smccli.bench.trial_cost` as a script (``python trial_probe.py TREE SCENE
TRIALS SEED``) with ``PYTHONPATH`` set to the checkout to measure, possibly an older
commit: it therefore imports nothing of smc at module level and finds what it times by
name, skipping names that commit does not have. Prints one JSON object.

Each timed function keeps its inclusive wall time [s] and call count. Rendering and
perception are also split by who asked: looking again during an action (under
``TreeExecutor.execute``) or a decision (everything else).
"""

from __future__ import annotations

import functools
import importlib
import json
import os
import sys
import time
from collections import defaultdict
from typing import Any

TIMED = {
    "physics": ("mujoco", None, "mj_step"),
    "sim_step": ("smccli.world.sim", "Sim", "step"),
    "lidar": ("smccli.world.sim", "Sim", "lidar"),
    "steering": ("smccli.world.controller", "CartesianController", "update"),
    "render": ("smccli.world.sim", "Sim", "render_camera"),
    "perception": ("smccli.perception.clusters", None, "clusters_from_frame"),
    "room": ("smccli.perception.room", None, "room_histogram"),
    "align": ("smccli.perception.scan", None, "align_scans"),
    "decide": ("smccli.execute.policy", "TreePolicy", "decide"),
    "action": ("smccli.execute.executor", "TreeExecutor", "execute"),
    "trial": ("smccli.execute.campaign", None, "run_trial"),
}
"""Stage -> (module, class or None, function)."""
SPLIT = ("render", "perception", "lidar", "room", "align")
"""Stages also counted by the caller they ran under (``action`` or ``decision``), each call's
time kept too."""

_spent: dict[str, float] = defaultdict(float)
_calls: dict[str, int] = defaultdict(int)
_per_call: dict[str, list[float]] = defaultdict(list)
_active: list[str] = []


def _timed(stage: str, fn: Any) -> Any:
    @functools.wraps(fn)
    def timed(*args: Any, **kwargs: Any) -> Any:
        _active.append(stage)
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            dt = time.perf_counter() - t0
            _active.pop()
            _spent[stage] += dt
            _calls[stage] += 1
            if stage in SPLIT:
                caller = "action" if "action" in _active else "decision"
                _spent[f"{stage}:{caller}"] += dt
                _per_call[f"{stage}:{caller}"].append(1e3 * dt)

    return timed


def _install() -> list[str]:
    """Wrap every stage this checkout has; the stages it lacks."""
    missing = []
    for stage, (module, cls, name) in TIMED.items():
        mod = importlib.import_module(module)
        owner = getattr(mod, cls, None) if cls else mod
        fn = getattr(owner, name, None) if owner is not None else None
        if fn is None:
            missing.append(stage)
            continue
        wrapped = _timed(stage, fn)
        setattr(owner, name, wrapped)
        if cls is None:  # ``from module import name`` elsewhere holds the original
            for other in list(sys.modules.values()):
                if getattr(other, name, None) is fn and other is not mod:
                    setattr(other, name, wrapped)
    return missing


def main(tree_path: str, scene: str, trials: int, seed: int) -> dict[str, Any]:
    os.environ.setdefault("MUJOCO_GL", "egl")
    from smccli.execute import campaign
    from smccli.execute.episode import resolve

    missing = _install()
    tree, sc = resolve(campaign.Path(tree_path), scene)
    t0 = time.perf_counter()
    results = campaign.run_trials(tree, sc, trials=trials, seed=seed, workers=1)
    wall = time.perf_counter() - t0
    return {
        "wall_s": wall,
        "spent_s": dict(_spent),
        "calls": dict(_calls),
        "missing": missing,
        "latency_ms": [ms for r in results for ms in r.latency_ms],
        "perceive_ms": [ms for r in results for ms in r.perceive_ms],
        "match_ms": [ms for r in results for ms in r.match_ms],
        "per_call_ms": dict(_per_call),
        "outcomes": [[r.index, r.outcome, r.path, r.reason] for r in results],
    }


if __name__ == "__main__":
    tree_arg, scene_arg, n, s = sys.argv[1:5]
    print(json.dumps(main(tree_arg, scene_arg, int(n), int(s))))
