"""What a trial costs beside its physics, here and at an older commit:
``python -m smccli.bench.trial_cost [--baseline REV]``.

For bench_pick with ideal sensors, bench_pick through the realistic sensors (the bench
scene ``bench_pick_realistic``, the sample tree) and rooms (lidar): each checkout compiles
its own sample tree, then runs the same ``--trials`` trials (``--seed``) in one process
(:mod:`smccli.bench.trial_probe`), the two checkouts taking turns for ``--rounds`` rounds so
that both see the same machine. Reported per checkout, as ratios where the machine's speed
varies: a trial's wall time over its ``mj_step`` time, steering's (the Cartesian
controller) and looking again's (rendering and perceiving during an action) share of a
trial, and decision latency p50/p95 [ms] (perceive + match) with its perception part, and
per stage of a decision the p50/p95 of a call and the calls per decision. The
outcomes (outcome, path, reason per trial) of the two checkouts must be the same, else
exit 1. Writes ``docs/bench_trial_cost.json`` (``--out``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from smccli.bench.meta import machine, write_rows
from smccli.bench.paper import REPO

PROBE = Path(__file__).with_name("trial_probe.py")
SCENARIOS = {
    "bench_pick ideal": ("bench_pick", "bench_pick"),
    "bench_pick realistic": ("bench_pick", "smccli/bench/scenes/bench_pick_realistic/scene.yaml"),
    "rooms": ("rooms", "rooms"),
}
"""Scenario -> (sample logs compiled into its tree, scene: a name or a checkout's path)."""


@contextmanager
def checkout(rev: str) -> Iterator[Path]:
    """A temporary worktree of ``rev`` (removed afterwards)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "smc"
        subprocess.run(
            ["git", "worktree", "add", "--detach", str(path), rev],
            cwd=REPO,
            check=True,
            capture_output=True,
        )
        try:
            yield path
        finally:
            subprocess.run(
                ["git", "worktree", "remove", "--force", str(path)], cwd=REPO, capture_output=True
            )


def _python(code: Path, *args: str) -> str:
    env = {**os.environ, "PYTHONPATH": str(code), "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    proc = subprocess.run(
        [sys.executable, *args], cwd=code, env=env, capture_output=True, text=True
    )
    if proc.returncode != 0:
        raise SystemExit(f"{code}: {' '.join(args[:3])} failed: {proc.stderr.strip()[-500:]}")
    return proc.stdout


def _tree(code: Path, logs: str, folder: Path) -> Path:
    tree = folder / f"{logs}.json"
    paths = sorted(str(p) for p in (code / "sample_logs" / logs).glob("*.mcap"))
    _python(code, "-m", "smccli.cli", "compile", *paths, "-o", str(tree))
    return tree


def _summary(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """One checkout's rounds of one scenario: the ratios, each round's and the median."""

    def ratio(num: str, den: str) -> float:
        return float(np.median([r["spent_s"].get(num, 0.0) / r["spent_s"][den] for r in runs]))

    look = [
        (r["spent_s"].get("render:action", 0) + r["spent_s"].get("perception:action", 0))
        / r["spent_s"]["trial"]
        for r in runs
    ]
    latency = [ms for r in runs for ms in r["latency_ms"]]
    perceive = [ms for r in runs for ms in r["perceive_ms"]]
    return {
        "decision_stages_ms": _decision_stages(runs, len(latency)),
        "trial_over_physics": ratio("trial", "physics"),
        "steering_over_physics": ratio("steering", "physics"),
        "looking_share_of_trial": float(np.median(look)),
        "decision_p50_ms": float(np.percentile(latency, 50)),
        "decision_p95_ms": float(np.percentile(latency, 95)),
        "perceive_p50_ms": float(np.percentile(perceive, 50)),
        "trials_per_s": float(np.median([len(r["outcomes"]) / r["wall_s"] for r in runs])),
        "stages_s": runs[-1]["spent_s"],
        "calls": runs[-1]["calls"],
        "missing_stages": runs[-1]["missing"],
    }


def _decision_stages(runs: list[dict[str, Any]], decisions: int) -> dict[str, dict[str, float]]:
    """Per stage of a decision (rendering, the clusters' or the room's perception, a scan's
    alignment, matching): p50 and p95 of one call [ms] and calls per decision. A checkout
    whose probe kept no call times (or lacks the stage) has none."""
    calls = {k.split(":")[0]: k for k in runs[0].get("per_call_ms", {}) if k.endswith(":decision")}
    out = {}
    for stage, key in sorted(calls.items()):
        ms = [x for r in runs for x in r["per_call_ms"].get(key, [])]
        if ms:
            out[stage] = _percentiles(ms, len(ms) / max(decisions, 1))
    match = [ms for r in runs for ms in r["match_ms"]]
    if match:
        out["match"] = _percentiles(match, 1.0)
    return out


def _percentiles(ms: list[float], per_decision: float) -> dict[str, float]:
    return {
        "p50": float(np.percentile(ms, 50)),
        "p95": float(np.percentile(ms, 95)),
        "per_decision": per_decision,
    }


def run(baseline: str, trials: int, seed: int, rounds: int) -> tuple[list[dict[str, Any]], bool]:
    """Rows (scenario, checkout, summary) and whether every scenario's outcomes agreed."""
    rows, same = [], True
    with checkout(baseline) as old, tempfile.TemporaryDirectory() as tmp:
        codes = {"baseline": old, "current": REPO}
        trees = {}
        for label, code in codes.items():
            (Path(tmp) / label).mkdir()
            for logs in {v[0] for v in SCENARIOS.values()}:
                trees[label, logs] = _tree(code, logs, Path(tmp) / label)
        for scenario, (logs, scene) in SCENARIOS.items():
            runs: dict[str, list[dict[str, Any]]] = {k: [] for k in codes}
            for _ in range(rounds):
                for label, code in codes.items():
                    where = str(code / scene) if scene.endswith(".yaml") else scene
                    args = (str(trees[label, logs]), where, str(trials), str(seed))
                    runs[label].append(json.loads(_python(code, str(PROBE), *args)))
            agree = all(
                r["outcomes"] == runs["baseline"][0]["outcomes"] for v in runs.values() for r in v
            )
            same &= agree
            for label, rs in runs.items():
                rows.append(
                    {
                        "scenario": scenario,
                        "checkout": label,
                        "same_outcomes": agree,
                        **_summary(rs),
                    }
                )
    return rows, same


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", default="48841bb", help="Commit to compare with.")
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--seed", type=int, default=4242)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "bench_trial_cost.json")
    args = ap.parse_args(argv)
    meta = machine()
    rows, same = run(args.baseline, args.trials, args.seed, args.rounds)
    write_rows(
        args.out,
        "smccli.bench.trial_cost",
        argv,
        meta,
        rows,
        baseline=args.baseline,
        trials=args.trials,
        seed=args.seed,
        same_outcomes=same,
    )
    for r in rows:
        print(
            f"{r['scenario']:22s} {r['checkout']:8s} "
            f"trial/physics {r['trial_over_physics']:.2f}  "
            f"steering/physics {r['steering_over_physics']:.2f}  "
            f"looking {100 * r['looking_share_of_trial']:.0f} %  "
            f"decision p50 {r['decision_p50_ms']:.0f} ms (perceive {r['perceive_p50_ms']:.0f})  "
            f"{r['trials_per_s']:.2f} trials/s"
        )
        stages = r["decision_stages_ms"]
        if stages:
            print(
                f"{'':31s}decision stages p50: "
                + ", ".join(
                    f"{k} {v['p50']:.1f} ms x{v['per_decision']:.1f}" for k, v in stages.items()
                )
            )
    if not same:
        print("outcomes differ between the checkouts", file=sys.stderr)
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
