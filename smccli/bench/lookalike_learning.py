"""The learning curve on the look-alike family: ``python -m smccli.bench.lookalike_learning
[--demos 1 2 4 8] [--trials 150] [--seed S] [--workers 2]``.

Issue 38, part 3. The learning curve (:mod:`smccli.bench.learning`) runs its trees among one
fixed grey bar; here the same trees meet the look-alike family (:mod:`smccli.bench.lookalike`).
The clumsy demonstrations of operators ``S`` to ``S + 7`` are recorded in the learning
scene (:func:`~smccli.bench.learning.record_demos`), the first 1, 2, 4 and 8 compiled into
one tree each, and every tree runs the family's trials ``0 ... N-1`` of seed ``S``: the same
look-alike, layout and sensors per trial for every tree, so the curve compares trees, not
draws. With one demonstration this is the family bench itself (its first ``N`` trials).

Reported per tree: the goal's figure (:func:`goal_band`: grey look-alikes up to
:data:`GOAL_GREY` a person can tell from the white box on the camera image), success by
grey band and by gap band over the trials a person can tell apart, and the
indistinguishable trials apart. ``--seed`` defaults to development seed 0; ``held-out`` is
the family bench's held-out seed. Writes ``docs/bench_lookalike_learning.json`` (or
``docs/held_out/``).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from smccli.bench import lookalike
from smccli.bench.learning import REPO, SCENE, clumsy_script, merged_trees, record_demos
from smccli.bench.meta import machine, write_rows
from smccli.bench.seeds import results_dir, seed_option

GOAL_GREY = 0.65
"""Issue 38's goal counts the grey look-alikes up to this grey level (the white box: 0.95)."""
GOAL_BAND = f"greys <= {GOAL_GREY}"


def in_goal(row: dict[str, Any]) -> bool:
    """Whether a trial's look-alike is one of the goal's: a grey of at most :data:`GOAL_GREY`."""
    return row["grey"] is not None and row["grey"] <= GOAL_GREY


def goal_band(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Success over the goal's trials a person can tell apart (Wilson 95 %), the
    indistinguishable ones counted apart (:func:`~smccli.bench.lookalike.band_table`)."""
    return lookalike.band_table(rows, lambda r: GOAL_BAND if in_goal(r) else None, [GOAL_BAND])[0]


def curve_row(n: int, rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """One tree's point of the curve: the goal's band, then :func:`lookalike.summarize`."""
    failed = [
        {k: r[k] for k in ("trial", "kind", "grey", "gap_m", "outcome", "reason")}
        for r in rows
        if not r["success"]
    ]
    return {
        "demonstrations": n,
        "trials": len(rows),
        "goal": goal_band(rows),
        **lookalike.summarize(rows),
        "failed_trials": failed,
    }


def row_line(row: dict[str, Any]) -> str:
    """A curve point on one line: the goal's figure and everything's."""
    g, a = row["goal"], row["overall"]
    lo, hi = g["ci95"]
    return (
        f"{row['demonstrations']} demonstration(s): goal {g['successes']}/{g['trials']} "
        f"({100 * lo:.1f}-{100 * hi:.1f} %), all told apart {a['successes']}/{a['trials']}, "
        f"failures {a['failures']}"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--demos", type=int, nargs="+", default=[1, 2, 4, 8])
    ap.add_argument("--trials", type=int, default=150)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=seed_option("lookalike"), default=0, help="or held-out")
    ap.add_argument("--calibration-layouts", type=int, default=lookalike.CALIBRATION_LAYOUTS)
    ap.add_argument("--out", type=Path, help="docs/bench_lookalike_learning.json, or held_out/")
    args = ap.parse_args(argv)
    args.out = args.out or results_dir(args.seed) / "bench_lookalike_learning.json"
    meta = machine()
    cal = lookalike.calibrate(args.calibration_layouts)
    points = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        logs = record_demos(work, max(args.demos), first=args.seed)
        for n, tree in merged_trees(logs, args.demos, work):
            rows = lookalike.run_trials(
                tree, args.seed, range(args.trials), args.workers, cal["threshold"]
            )
            points.append(curve_row(n, rows))
            print(row_line(points[-1]), flush=True)
        redone = [p.name for p in logs if not p.stem.endswith("_0")]
    write_rows(
        args.out,
        "smccli.bench.lookalike_learning",
        argv,
        meta,
        points,
        scene=str(SCENE.relative_to(REPO)),
        scripts=[clumsy_script(args.seed + k) for k in range(max(args.demos))],
        redone=redone,
        family=lookalike.FAMILY,
        calibration=cal,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
