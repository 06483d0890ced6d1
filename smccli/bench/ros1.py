"""The tree on a robot over ROS 1: ``python -m smccli.bench.ros1``.

Issue 39. A roscore of its own (127.0.0.1, a free port); per trial ``smc sim --ros1`` on
the layout ``smc replay --seed S`` draws for that trial, and ``smc run --ros1`` driving it,
both real processes. Each trial is also replayed in-process on the same layout. Reports per
scene: the success rate over ROS (Wilson 95 %), how many trials made replay's decisions
(same edges, goals within 1 mm, largest goal difference), and the latency from the receipt
of a decision's image to the first command after it (p50, p95) beside replay's decision
latency (perceive + match) on the same layouts. bench_pick ``--trials`` (20), rooms
``--rooms-trials`` (20). Writes ``docs/bench_ros1.json`` (``--out``).
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import argparse  # noqa: E402
import json  # noqa: E402
import signal  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from smccli.bench.meta import machine, write_rows  # noqa: E402
from smccli.bench.paper import demo_tree  # noqa: E402
from smccli.bench.seeds import results_dir, seed_option  # noqa: E402
from smccli.execute.campaign import wilson  # noqa: E402
from smccli.execute.episode import episode, layout_for, resolve  # noqa: E402
from smccli.ros.master import roscore  # noqa: E402
from smccli.ros.sim_robot import sim_topic_map  # noqa: E402
from smccli.world.scene import ROBOT_KEY, Layout  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
GOAL_TOLERANCE = 1e-3
"""Goals within this of replay's count as the same decision [m, rad]."""


def _smc(*args: str) -> list[str]:
    return [sys.executable, "-m", "smccli.cli", *args]


def ros_trial(
    env: dict[str, str], scene: str, tree: Path, topics: Path, layout: Path, work: Path
) -> tuple[dict[str, Any], dict[str, Any]]:
    """One trial over ROS: (the node's report, the sim's verdict)."""
    sim_report, run_report, log = work / "sim.json", work / "run.json", work / "sim.log"
    with open(log, "w") as out:
        sim = subprocess.Popen(
            _smc("sim", "--ros1", "--scene", scene, "--layout", str(layout))
            + ["--topics", str(topics), "--report", str(sim_report), "--force"],
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    try:
        while "running" not in log.read_text():
            if sim.poll() is not None:
                raise RuntimeError(log.read_text())
            time.sleep(0.1)
        node = subprocess.run(
            _smc("run", str(tree), "--ros1", "--topics", str(topics))
            + ["--report", str(run_report), "--force"],
            env=env,
            capture_output=True,
            text=True,
            timeout=900,
        )
        if node.returncode == 2:
            raise RuntimeError(node.stderr)
    finally:
        sim.send_signal(signal.SIGINT)
        sim.wait(timeout=120)
    return json.loads(run_report.read_text()), json.loads(sim_report.read_text())


def layout_file(lay: Layout) -> dict[str, list[float]]:
    """A layout as its file holds it (the base's start as ``[x, y, yaw]``)."""
    return {
        k: [float(p[0]), float(p[1]), float(p[3])] if k == ROBOT_KEY else [float(v) for v in p]
        for k, p in lay.items()
    }


def goal_difference(ros: list[dict[str, Any]], replay: list[dict[str, Any]]) -> float | None:
    """The largest difference between the two runs' goals (position [m] or yaw [rad]), None
    when their edges differ."""
    if [d["chosen"] for d in ros] != [d["chosen"] for d in replay]:
        return None
    diffs = [
        float(np.max(np.abs(np.subtract(a["mapped_goal"], b["mapped_goal"]))))
        for a, b in zip(ros, replay, strict=True)
        if a["mapped_goal"] is not None and b["mapped_goal"] is not None
    ]
    return max(diffs, default=0.0)


def scene_campaign(
    env: dict[str, str], scene_name: str, trials: int, seed: int, work: Path
) -> dict[str, Any]:
    """``trials`` layouts of ``scene_name`` over ROS and in replay."""
    tree_path = demo_tree(scene_name, work)
    tree, scene = resolve(tree_path, None)
    topics = work / f"{scene_name}_map.yaml"
    topics.write_text(yaml.safe_dump(sim_topic_map(scene), sort_keys=False))
    ok = same = 0
    worst = 0.0
    latency_ros: list[float] = []
    latency_replay: list[float] = []
    outcomes: dict[str, int] = {}
    t0 = time.perf_counter()
    for trial in range(trials):
        lay = layout_for(scene, seed, trial)
        layout = work / f"{scene_name}_layout.yaml"
        layout.write_text(yaml.safe_dump(layout_file(lay)))
        ros, verdict = ros_trial(env, scene_name, tree_path, topics, layout, work)
        replay = episode(tree, scene, lay)
        ok += bool(verdict["success"])
        outcomes[ros["outcome"]] = outcomes.get(ros["outcome"], 0) + 1
        diff = goal_difference(ros["decisions"], [d.to_json() for d in replay.decisions])
        same += diff is not None and diff <= GOAL_TOLERANCE
        worst = max(worst, np.inf if diff is None else diff)
        latency_ros += ros["image_to_command_ms"]
        latency_replay += replay.latencies_ms
        print(
            f"{scene_name} trial {trial}: {ros['outcome']}, task "
            f"{'done' if verdict['success'] else 'failed'}, goal difference {diff}",
            flush=True,
        )
    lo, hi = wilson(ok, trials)
    return {
        "scene": scene_name,
        "trials": trials,
        "successes": ok,
        "success_rate": ok / trials,
        "ci95": [lo, hi],
        "node_outcomes": outcomes,
        "same_decisions_as_replay": same,
        "largest_goal_difference": worst,
        "image_to_command_ms": _percentiles(latency_ros),
        "replay_decision_ms": _percentiles(latency_replay),
        "wall_s": time.perf_counter() - t0,
    }


def _percentiles(values: list[float]) -> dict[str, float | int | None]:
    if not values:
        return {"n": 0, "p50": None, "p95": None}
    p50, p95 = np.percentile(values, [50, 95])
    return {"n": len(values), "p50": float(p50), "p95": float(p95)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--rooms-trials", type=int, default=20)
    ap.add_argument("--seed", type=seed_option("ros1"), default=11, help="or held-out")
    ap.add_argument("--work", type=Path, default=REPO / "bench_results")
    ap.add_argument("--out", type=Path, help="docs/bench_ros1.json, or docs/held_out/...")
    args = ap.parse_args(argv)
    args.out = args.out or results_dir(args.seed) / "bench_ros1.json"
    meta = machine()
    rows = []
    args.work.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as home, roscore(Path(home)) as env:
        for scene, trials in (("bench_pick", args.trials), ("rooms", args.rooms_trials)):
            if trials <= 0:
                continue
            row = scene_campaign(env, scene, trials, args.seed, args.work)
            rows.append(row)
            lat, rep = row["image_to_command_ms"], row["replay_decision_ms"]
            print(
                f"{scene}: {row['successes']}/{trials} over ROS, "
                f"{row['same_decisions_as_replay']} with replay's decisions; image to command "
                f"p50 {lat['p50']:.0f} ms, p95 {lat['p95']:.0f} ms (replay's decisions "
                f"p50 {rep['p50']:.0f} ms, p95 {rep['p95']:.0f} ms)",
                flush=True,
            )
    write_rows(
        args.out, "smccli.bench.ros1", argv, meta, rows, seed=args.seed, tolerance=GOAL_TOLERANCE
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
