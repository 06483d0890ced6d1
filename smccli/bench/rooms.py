"""The mobile base's benchmark (paper 4.2): ``python -m smccli.bench.rooms``.

1. Compile the two sample demonstrations of ``rooms`` (from different starts, one per
   arrow) and check the tree's shape: two merged SMCs, then a branch per arrow.
2. ``--trials`` (200) randomised trials: a start anywhere within +-0.5 m and +-45 deg of the
   nominal one in room 1, the arrow drawn at random; success = within 10 cm and 10 deg of
   the arrow's goal, nothing touched.
3. The same with odometry drift (``--drift``, 2 % of the distance and 0.02 rad per metre).
4. Decision latency measured serially (one process, so the other worker does not share the
   cores): render + room histogram, scan alignment (ICP), matching, p50 and p95.

Writes ``docs/bench_rooms.json`` and ``docs/img/bench_rooms.png`` (``--out``).
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from smccli.bench.meta import campaign_line, machine  # noqa: E402
from smccli.bench.paper import REPO, campaign, demo_tree, strip_trials  # noqa: E402
from smccli.bench.seeds import results_dir, seed_option  # noqa: E402
from smccli.execute.episode import episode, layout_for, resolve  # noqa: E402
from smccli.learn.tree import ROOT  # noqa: E402
from smccli.outputs import check_output, write_atomic  # noqa: E402
from smccli.world.sim import OdometryDrift  # noqa: E402


def tree_shape(tree: Any) -> dict[str, Any]:
    """Supports along the tree: the merged chain from the root, then the branches."""
    chain, node = [], ROOT
    while len(tree.children(node)) == 1:
        (edge,) = tree.children(node)
        chain.append(edge.support)
        node = edge.child
    return {"chain_supports": chain, "branches": [e.support for e in tree.children(node)]}


def serial_latency(tree: Any, scene: Any, episodes: int, seed: int) -> dict[str, Any]:
    """Decision latency over ``episodes`` episodes run in this process [ms]."""
    per, icp, match, total = [], [], [], []
    for i in range(episodes):
        r = episode(tree, scene, layout_for(scene, seed + 1000, i))
        for d in r.decisions:
            per.append(1e3 * d.perceive_s)
            icp.append(1e3 * d.icp_s)
            match.append(1e3 * (d.match_s - d.icp_s))
            total.append(1e3 * d.latency_s)

    def pct(v: list[float]) -> dict[str, float]:
        return {"p50": float(np.percentile(v, 50)), "p95": float(np.percentile(v, 95))}

    return {
        "decisions": len(total),
        "render_and_histogram": pct(per),
        "icp": pct(icp),
        "match_without_icp": pct(match),
        "total": pct(total),
    }


def plot(plain: dict[str, Any], drifted: dict[str, Any] | None, out: Path) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(7, 3.2))
    runs = [("no drift", plain, "#4c8bf5")]
    if drifted is not None:
        runs.append(("odometry drift", drifted, "#f5a04c"))
    width = 0.4
    for k, (label, s, colour) in enumerate(runs):
        bands = [b for b in s["by_band"] if b["trials"]]
        x = np.arange(len(bands)) + (k - 0.5 * (len(runs) - 1)) * width
        rate = np.array([100 * b["success_rate"] for b in bands])
        lo = rate - np.array([100 * b["ci95"][0] for b in bands])
        hi = np.array([100 * b["ci95"][1] for b in bands]) - rate
        ax.bar(x, rate, width, yerr=[lo, hi], color=colour, capsize=2, label=label)
        ax.set_xticks(np.arange(len(bands)), [b["label"] for b in bands], fontsize=7)
    ax.set_ylim(80, 101)
    ax.set_ylabel("success [%]")
    ax.set_xlabel("start's distance from the nominal start in room 1")
    ax.legend(fontsize=8, loc="lower left")
    ax.set_title(
        f"rooms (paper 4.2): {plain['successes']}/{plain['trials']} trials"
        + (f", with drift {drifted['successes']}/{drifted['trials']}" if drifted else "")
        + " (bars: Wilson 95 %)",
        fontsize=9,
    )
    fig.tight_layout()
    path = out / "bench_rooms.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return str(path.relative_to(REPO)) if path.is_relative_to(REPO) else str(path)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m smccli.bench.rooms", description=__doc__.split("\n")[0]
    )
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--drift-trials", type=int, default=200, help="0: skip")
    ap.add_argument("--drift", type=float, default=0.02)
    ap.add_argument("--latency-episodes", type=int, default=30)
    ap.add_argument("--seed", type=seed_option("rooms"), default=0, help="or held-out")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--work", type=Path, default=REPO / "bench_results")
    ap.add_argument("--out", type=Path, help="docs/, or docs/held_out/")
    args = ap.parse_args(argv)
    args.out = args.out or results_dir(args.seed)
    check_output(args.out / "bench_rooms.json", force=True)

    tree_path = demo_tree("rooms", args.work)
    tree, scene = resolve(tree_path, None)
    results: dict[str, Any] = {
        "command": "python -m smccli.bench.rooms "
        + " ".join(argv if argv is not None else sys.argv[1:]),
        "machine": machine(),
        "tree": tree_shape(tree),
    }
    results["latency_serial_ms"] = serial_latency(tree, scene, args.latency_episodes, args.seed)
    plain = campaign("rooms", tree_path, args.trials, seed=args.seed, workers=args.workers)
    results["rooms"] = strip_trials(plain)
    drifted = None
    if args.drift_trials > 0:
        drifted = campaign(
            "rooms with drift",
            tree_path,
            args.drift_trials,
            seed=args.seed + 1,
            workers=args.workers,
            drift=OdometryDrift(args.drift, args.drift),
        )
        results["rooms_drift"] = strip_trials(drifted)
    results["figure"] = plot(plain, drifted, args.out / "img")
    results["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S")
    path = args.out / "bench_rooms.json"
    write_atomic(path, json.dumps(results, indent=1, allow_nan=False) + "\n")
    lat = results["latency_serial_ms"]
    print(f"tree: {results['tree']}")
    for name in ("rooms", "rooms_drift"):
        if name in results:
            print(campaign_line(name, results[name]))
    print(
        f"decision latency (serial, {lat['decisions']} decisions): total p50 "
        f"{lat['total']['p50']:.1f} / p95 {lat['total']['p95']:.1f} ms; render + histogram "
        f"{lat['render_and_histogram']['p50']:.1f} / {lat['render_and_histogram']['p95']:.1f}, "
        f"ICP {lat['icp']['p50']:.1f} / {lat['icp']['p95']:.1f}, match "
        f"{lat['match_without_icp']['p50']:.2f} / {lat['match_without_icp']['p95']:.2f} ms"
    )
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
