"""An object pushed while the robot reaches for it: ``python -m smccli.bench.look``.

Issue 27, part 2 (look again). bench_pick's sample tree, ideal sensors, and the tree of
the same script recorded through the realistic sensors (``bench_pick_realistic``, as
:mod:`smccli.bench.paper` builds it): ``--trials`` (100) random layouts each, in every one
the white box pushed 5 cm in a direction drawn uniformly, at a time drawn uniformly

- *early*: 0.2-1.0 s into the 2.0-2.4 s approach (the hand still far from the box);
- *late*: 1.4-1.8 s in (the hand over the box, its fingers hiding it);

with looking again (the executor's ``LOOK_PERIOD``) and without (0). The push is the
world's (:meth:`~smccli.world.truth.Truth.push_object`): control learns of it only through the
camera. Wilson 95 % intervals. Writes ``docs/bench_look.json`` (``--out``).
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from smccli.bench.meta import machine, write_rows  # noqa: E402
from smccli.bench.paper import VARIANT_DIR, demo_tree, noisy_demo_tree  # noqa: E402
from smccli.bench.seeds import results_dir, seed_option  # noqa: E402
from smccli.execute.campaign import wilson  # noqa: E402
from smccli.execute.episode import episode, layout_for, resolve  # noqa: E402
from smccli.execute.executor import LOOK_PERIOD  # noqa: E402
from smccli.world.sim import Sim  # noqa: E402
from smccli.world.truth import Push  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
PUSH = 0.05
"""How far the box is pushed [m]."""
WINDOWS = {"early": (0.2, 1.0), "late": (1.4, 1.8)}
"""When, in seconds from the start of the first action (the approach)."""


def pushed_campaign(
    tree_path: Path, scene_file: Path | None, trials: int, window: str, look: float, seed: int
) -> dict[str, Any]:
    """``trials`` episodes, each with the white box pushed :data:`PUSH` in ``window``."""
    tree, scene = resolve(tree_path, scene_file)
    rng = np.random.default_rng(seed)
    lo, hi = WINDOWS[window]
    sim = Sim(scene, layout_for(scene, seed, 0))
    ok = 0
    failures: dict[str, int] = {}
    t0 = time.perf_counter()
    try:
        for t in range(trials):
            a, at = rng.uniform(-np.pi, np.pi), rng.uniform(lo, hi)
            push = Push("white_box", at, PUSH * np.cos(a), PUSH * np.sin(a))
            r = episode(
                tree, scene, layout_for(scene, seed, t), sim=sim, push=push, look_period=look
            )
            ok += r.success
            if not r.success:
                failures[r.outcome] = failures.get(r.outcome, 0) + 1
    finally:
        sim.close()
    lo_ci, hi_ci = wilson(ok, trials)
    return {
        "trials": trials,
        "successes": ok,
        "success_rate": ok / trials,
        "ci95": [lo_ci, hi_ci],
        "failures": failures,
        "wall_s": time.perf_counter() - t0,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--seed", type=seed_option("look"), default=0, help="or held-out")
    ap.add_argument("--work", type=Path, default=REPO / "bench_results")
    ap.add_argument("--out", type=Path, help="docs/bench_look.json, or docs/held_out/...")
    args = ap.parse_args(argv)
    args.out = args.out or results_dir(args.seed) / "bench_look.json"
    meta = machine()
    trees = {
        "ideal": (demo_tree("bench_pick", args.work), None),
        "realistic": (
            noisy_demo_tree(args.work),
            VARIANT_DIR / "bench_pick_realistic" / "scene.yaml",
        ),
    }
    runs = [
        ("ideal", "early", LOOK_PERIOD),
        ("ideal", "early", 0.0),
        ("ideal", "late", LOOK_PERIOD),
        ("realistic", "early", LOOK_PERIOD),
        ("realistic", "early", 0.0),
    ]
    rows = []
    for sensors, window, look in runs:
        tree, scene = trees[sensors]
        s = pushed_campaign(tree, scene, args.trials, window, look, args.seed)
        row = {"sensors": sensors, "push": window, "look_period_s": look, **s}
        rows.append(row)
        lo, hi = s["ci95"]
        print(
            f"{sensors}, {window} push, look every {look:g} s: {s['successes']}/{s['trials']} "
            f"({100 * lo:.1f}-{100 * hi:.1f} %), failures {s['failures']}",
            flush=True,
        )
    write_rows(args.out, "smccli.bench.look", argv, meta, rows, push_m=PUSH, windows=WINDOWS)
    return 0


if __name__ == "__main__":
    sys.exit(main())
