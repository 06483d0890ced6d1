"""Replay duration against the demonstration's: ``python -m smccli.bench.duration``.

Paper section 6: executions are shorter than the demonstration because the waiting at
fragment boundaries is dropped. Measured here, in simulated time only:

- a slow, pausing ``bench_pick`` demonstration (:func:`pausing_script`: the sample task
  with waits of 1-2 s between steps and a hesitant operator), recorded from a random
  layout, compiled and replayed over a campaign (``--slow-trials``, 100);
- each scene of ``sample_logs/``: its logs compiled into one tree, a campaign of
  ``--trials`` (8) trials;
- the sample ``bench_pick`` tree at ``--speed`` = its limit (:func:`speed_limit`).

A trial's ratio is its duration (first decision to the last action's end) over the
demonstration of the path it took: for each edge, the mean over its source fragments of
the *untrimmed* fragment (``t1 - t0`` plus the idle head and tail compile trimmed), i.e.
what the operator took from one decision point to the next. The report's own
``duration_ratio`` divides by the trimmed fragments, the demonstrated motion; both are
written.

Writes ``docs/bench_duration.json`` (``--out``).
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from smccli.bench.meta import machine  # noqa: E402
from smccli.execute.campaign import run_campaign  # noqa: E402
from smccli.execute.executor import speed_limit  # noqa: E402
from smccli.learn.chain import fragments  # noqa: E402
from smccli.learn.compile import compile_logs  # noqa: E402
from smccli.learn.tree import Tree, load_tree  # noqa: E402
from smccli.logs import read_log  # noqa: E402
from smccli.outputs import check_output, write_atomic  # noqa: E402

REPO = Path(__file__).resolve().parents[2]


def pausing_script(wait: float = 1.5, speed: float = 0.10) -> str:
    """A bench_pick teleop script: the sample task (``sample_logs/bench_pick/demo.yaml``)
    at ``speed`` [m/s] by a hesitant operator who waits ``wait`` to ``wait * 4/3`` s
    between steps [s]."""
    w, long = f"{wait:g}", f"{wait * 4 / 3:.2f}"
    return f"""# A slow, hesitant operator: the sample task with pauses between steps.
scene: bench_pick
description: "White box into the orange box, slowly, pausing between steps"
speed: {speed:g}
tremor: 0.0005
hesitation: 0.8
speed_variation: 0.2
steps:
  - wait: {long}
  - move_to: {{object: white_box, offset: [0, 0, 0.12]}}
  - wait: {w}
  - move_to: {{object: white_box, offset: [0, 0, 0.0]}}
  - wait: {w}
  - gripper: close
  - wait: {w}
  - mark: grasp
  - wait: {long}
  - move_to: {{object: white_box, offset: [0, 0, 0.15]}}
  - wait: {w}
  - move_to: {{object: orange_box, offset: [0, 0, 0.17]}}
  - wait: {long}
  - move_to: {{object: orange_box, offset: [0, 0, 0.04]}}
  - wait: {w}
  - gripper: open
  - wait: {w}
  - mark: release
  - wait: {w}
  - move_to: {{object: orange_box, offset: [0, 0, 0.2]}}
"""


def untrimmed_durations(tree: Tree, logs: list[Path]) -> dict[str, float]:
    """Per edge id: the mean over its sources of the untrimmed fragment's duration [s]
    (the logs are segmented again, with the tree's parameters)."""
    spans: dict[tuple[str, float, float], float] = {}
    for path in logs:
        log = read_log(path)
        for f in fragments(log, tree.params):
            spans[(log.sha256, round(f.t0, 3), round(f.t1, 3))] = (
                f.t1 - f.t0 + f.idle_head + f.idle_tail
            )
    out = {}
    for e in tree.edges:
        ds = [spans.get((s.sha256, round(s.t0, 3), round(s.t1, 3)), s.t1 - s.t0) for s in e.sources]
        out[e.id] = float(np.mean(ds)) if ds else 0.0
    return out


def campaign_row(
    name: str, tree_path: Path, logs: list[Path], trials: int, workers: int, speed: float = 1.0
) -> dict[str, Any]:
    """A campaign of ``tree_path`` and its duration ratios (see the module docstring)."""
    tree = load_tree(tree_path)
    demo = untrimmed_durations(tree, logs)
    s = run_campaign(tree_path, trials=trials, workers=workers, speed=speed)
    ok = [r for r in s["trial_results"] if r["success"]]
    ratio = [r["duration"] / sum(demo[e] for e in r["path"]) for r in ok]
    motion = [r["duration"] / r["demo_duration"] for r in ok if r["demo_duration"] > 0]
    limit, edge, peak = speed_limit(tree)
    row = {
        "name": name,
        "scene": s["scene"],
        "logs": [str(p.relative_to(REPO)) if p.is_relative_to(REPO) else p.name for p in logs],
        "speed": speed,
        "speed_limit": limit if np.isfinite(limit) else None,
        "fastest_edge": edge,
        "fastest_peak_m_s": peak,
        "trials": s["trials"],
        "successes": s["successes"],
        "success_rate": s["success_rate"],
        "ci95": s["ci95"],
        "failures": {k: v for k, v in s["failures"].items() if v},
        "duration_s_p50": float(np.median([r["duration"] for r in ok])) if ok else None,
        "demo_s_p50": float(np.median([sum(demo[e] for e in r["path"]) for r in ok]))
        if ok
        else None,
        "ratio_p50": float(np.median(ratio)) if ratio else None,
        "ratio_p95": float(np.percentile(ratio, 95)) if ratio else None,
        "ratio_max": max(ratio, default=None),
        "ratio_to_motion_p50": float(np.median(motion)) if motion else None,
    }
    print(
        f"{name:18s} {row['successes']}/{row['trials']}  ratio p50 "
        f"{row['ratio_p50'] if row['ratio_p50'] is not None else float('nan'):.2f} "
        f"(to the motion {row['ratio_to_motion_p50'] or float('nan'):.2f}), "
        f"speed {speed:g} (limit {limit:.2f})",
        flush=True,
    )
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=8, help="per sample scene")
    ap.add_argument("--slow-trials", type=int, default=100)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=3, help="of the slow demonstration")
    ap.add_argument("--scenes", nargs="*", default=None, help="sample_logs folders")
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "bench_duration.json")
    args = ap.parse_args(argv)
    check_output(args.out, force=True)
    from smccli.record.session import RecordConfig, record

    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        script = d / "slow_demo.yaml"
        script.write_text(pausing_script())
        log = d / "slow.mcap"
        rec = record(
            RecordConfig(
                scene="bench_pick", script=script, seed=args.seed, output=log, randomize=True
            )
        )
        tree = d / "slow.json"
        compile_logs([log], tree)
        slow = campaign_row("bench_pick (slow)", tree, [log], args.slow_trials, args.workers)
        slow["log_duration_s"] = rec.duration
        slow["script"] = pausing_script()
        rows.append(slow)
        folders = sorted(p for p in (REPO / "sample_logs").iterdir() if p.is_dir())
        for folder in folders:
            if args.scenes is not None and folder.name not in args.scenes:
                continue
            logs = sorted(folder.glob("*.mcap"))
            tree = d / f"{folder.name}.json"
            compile_logs(logs, tree)
            rows.append(campaign_row(folder.name, tree, logs, args.trials, args.workers))
            if folder.name == "bench_pick":
                limit = speed_limit(load_tree(tree))[0]
                rows.append(
                    campaign_row(
                        "bench_pick at its speed limit",
                        tree,
                        logs,
                        args.trials,
                        args.workers,
                        speed=float(np.floor(limit * 100) / 100),
                    )
                )
    result = {
        "machine": machine(),
        "command": "python -m smccli.bench.duration " + " ".join(argv or sys.argv[1:]),
        "note": "durations are simulated time; ratio = replay duration / the untrimmed "
        "demonstration of the path taken; ratio_to_motion = / the trimmed fragments",
        "rows": rows,
    }
    write_atomic(args.out, json.dumps(result, indent=1, allow_nan=False) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
