"""The paper's benchmark (5.1) and companion campaigns: ``python -m smccli.bench.paper``.

1. Compile ``bench_pick``'s sample demonstration, check the scene's randomisation covers the
   paper's set-up (>= 0.5 m along the table, >= 0.25 m across, yaw over a full turn), run
   ``--trials`` (1288) randomised trials and plot success by distance band (Fig. 11) and the
   perception-time and task-duration histograms (Fig. 12).
2. Decision latency (perceive + match) measured serially at the scene's 320x240 camera,
   tree match time at a synthetic node with 1000 children built from real SMCs, trials/s.
3. The same benchmark on the Panda (``bench_pick_panda``, the robot of the paper's 5.1
   simulation): its own sample demonstration, ``--panda-trials`` (300) trials, Fig. 11.
4. Campaigns of ``--side-trials`` (100) on ``pick_place`` and ``weigh_sort``.
5. bench_pick's sample script recorded through the realistic sensors, compiled, and run in
   the variants of ``smccli/bench/scenes`` (``--variant-trials`` each, 1288):
   ``bench_pick_realistic`` (the realistic sensor models, :mod:`smccli.world.noise`),
   ``bench_pick_clutter`` (three distractors randomised over the table) and
   ``bench_pick_moving`` (the orange box randomised too), both also realistic. Fig. 10
   (initial positions of the white box, successes and failures) and Fig. 11 for each.

Every campaign's entry names its scene and sensor profile; the file names the commit.

Writes ``docs/bench_results.json`` and ``docs/img/bench_*.png`` (``--out``); logs and trees
go to ``bench_results/`` (git-ignored).
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from smccli.bench.meta import campaign_line, machine  # noqa: E402
from smccli.bench.seeds import results_dir, seed_option  # noqa: E402
from smccli.execute import campaign as cp  # noqa: E402
from smccli.execute.episode import layout_for, resolve  # noqa: E402
from smccli.execute.executor import EdgeStack, TreeExecutor, match_edges  # noqa: E402
from smccli.execute.sensing import Sensors  # noqa: E402
from smccli.learn.tree import ROOT, Edge, Tree  # noqa: E402
from smccli.outputs import check_output, write_atomic  # noqa: E402
from smccli.world.scene import Scene, load_scene  # noqa: E402

REPO = Path(__file__).resolve().parents[2]


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def demo_tree(scene: str, work: Path) -> Path:
    """The scene's sample logs (recorded from their scripts if absent) compiled into a tree."""
    from smccli.learn.compile import compile_logs
    from smccli.record.session import RecordConfig, record

    work.mkdir(parents=True, exist_ok=True)
    logs = []
    for script in sorted((REPO / "sample_logs" / scene).glob("*.yaml")):
        log = script.with_suffix(".mcap")
        if not log.exists():
            log = work / f"{scene}_{script.stem}.mcap"
            if not log.exists():
                record(RecordConfig(scene=scene, script=script, output=log, seed=0))
        logs.append(log)
    tree = work / f"{scene}_tree.json"
    compile_logs(logs, tree, rebuild=True)
    return tree


def noisy_demo_tree(work: Path) -> Path:
    """bench_pick's sample script recorded through the realistic sensors
    (``bench_pick_realistic``) and compiled with that scene's perception settings: what a
    user with a real camera teaches. Recorded once into ``work``."""
    from smccli.learn.compile import compile_logs
    from smccli.record.session import RecordConfig, record

    work.mkdir(parents=True, exist_ok=True)
    scene = VARIANT_DIR / "bench_pick_realistic" / "scene.yaml"
    script = work / "bench_pick_realistic_demo.yaml"
    text = (REPO / "sample_logs" / "bench_pick" / "demo.yaml").read_text()
    script.write_text(text.replace("scene: bench_pick\n", "scene: bench_pick_realistic\n"))
    log = work / "bench_pick_realistic_demo.mcap"
    if not log.exists():
        record(RecordConfig(scene=str(scene), script=script, output=log, seed=0))
    tree = work / "bench_pick_realistic_tree.json"
    compile_logs([log], tree, rebuild=True)
    return tree


def check_ranges(scene: Scene, obj: str) -> dict[str, Any]:
    """Does the object's randomisation cover the paper's set-up (0.5 m x 0.25 m, any yaw)?"""
    o = scene.object(obj)
    sx, sy = o.range_x[1] - o.range_x[0], o.range_y[1] - o.range_y[0]
    yaw = o.range_yaw[1] - o.range_yaw[0]
    along, across = max(sx, sy), min(sx, sy)
    ok = along >= 0.5 - 1e-6 and across >= 0.25 - 1e-6 and yaw >= 2 * math.pi - 1e-3
    return {
        "object": obj,
        "range_x": list(o.range_x),
        "range_y": list(o.range_y),
        "range_yaw": list(o.range_yaw),
        "along_m": along,
        "across_m": across,
        "yaw_rad": yaw,
        "covers_paper_setup": ok,
    }


def serial_latency(tree: Tree, scene: Scene, n: int = 20, seed: int = 99) -> dict[str, Any]:
    """Decision latency on an otherwise idle process: render + clusters + match [ms]."""
    from smccli.world.sim import Sim

    per, mat = [], []
    for i in range(n):
        sim = Sim(scene, layout_for(scene, seed, i))
        try:
            ctl = TreeExecutor(tree, Sensors(sim))
            sim.start_camera()  # GL warm-up, as an episode does
            dec, *_ = ctl.decide((ROOT,))
            per.append(1e3 * dec.perceive_s)
            mat.append(1e3 * dec.match_s)
        finally:
            sim.close()
    tot = np.add(per, mat)
    return {
        "p50": float(np.median(tot)),
        "p95": float(np.percentile(tot, 95)),
        "perceive_p50": float(np.median(per)),
        "match_p50": float(np.median(mat)),
        "decisions": n,
        "resolution": f"{scene.camera.width}x{scene.camera.height}",
    }


def match_1000(tree: Tree, scene: Scene, n_edges: int = 1000, reps: int = 200) -> dict[str, Any]:
    """Match time of one context against a node with ``n_edges`` children (real SMCs)."""
    from smccli.learn.contingency import match_context
    from smccli.perception import clusters_from_frame
    from smccli.world.sim import Sim

    real = list(tree.edges)
    edges = tuple(
        Edge(
            id=f"s{k}",
            parent=ROOT,
            child=f"c{k}",
            smc=real[k % len(real)].smc,
            support=1,
            sources=(),
        )
        for k in range(n_edges)
    )
    sim = Sim(scene, layout_for(scene, 0))
    frame = sim.render_camera()
    clusters = clusters_from_frame(frame, sim.robot_geometry(), tree.params.perception)
    sim.close()
    stack = EdgeStack.build(edges)
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        d, _ = match_edges(stack, clusters, None, tree.params)
        int(np.argmin(np.where(d < tree.params.t_hp, d, np.inf)))
        times.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    for e in edges:
        match_context(e.smc.perception, clusters, None, tree.params)
    loop = time.perf_counter() - t0
    return {
        "edges": n_edges,
        "clusters": len(clusters),
        "vectorised_ms_p50": 1e3 * float(np.median(times)),
        "vectorised_ms_p95": 1e3 * float(np.percentile(times, 95)),
        "per_edge_loop_ms": 1e3 * loop,
    }


def plots(summary: dict[str, Any], out: Path, name: str = "bench") -> list[str]:
    """Fig. 11 (success by distance band) and Fig. 12 (perception time, task duration),
    as ``<name>_success_by_band.png`` and ``<name>_timing.png``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    bands = [b for b in summary["by_band"] if b["trials"]]
    fig, ax = plt.subplots(figsize=(6, 3.6))
    x = np.arange(len(bands))
    rates = [100 * b["success_rate"] for b in bands]
    err = np.array(
        [
            [r - 100 * b["ci95"][0], 100 * b["ci95"][1] - r]
            for r, b in zip(rates, bands, strict=True)
        ]
    ).T
    ax.bar(x, rates, color="#4c8bf5", yerr=err, capsize=3)
    for xi, b in zip(x, bands, strict=True):
        ax.text(float(xi), 2, f"n={b['trials']}", ha="center", fontsize=7, color="white")
    ax.set_xticks(x, [b["label"].replace(" m", "") for b in bands], rotation=30, fontsize=8)
    ax.set_ylim(0, 105)
    ax.set_ylabel("success [%]")
    ax.set_xlabel("distance of the white box from the demonstrated position [m]")
    ax.set_title(
        f"{summary['scene']} ({summary['robot']}): "
        f"{100 * summary['success_rate']:.2f} % of {summary['trials']} "
        "trials (bars: Wilson 95 %)",
        fontsize=9,
    )
    fig.tight_layout()
    f11 = out / f"{name}_success_by_band.png"
    fig.savefig(f11, dpi=120)
    plt.close(fig)

    trials = summary["trial_results"]
    per = [v for t in trials for v in t["perceive_ms"]]
    dur = [t["duration"] for t in trials if t["success"]]
    demo = trials[0]["demo_duration"] if trials else 0.0
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.4))
    a.hist(per, bins=40, color="#f5a04c")
    a.set_xlabel("perception time per decision [ms]")
    a.set_ylabel("decisions")
    a.set_title("(a) perceive (render + clusters)", fontsize=9)
    b.hist(dur, bins=40, color="#4cc38a")
    if demo:
        b.axvline(demo, color="k", ls="--", label=f"demonstration {demo:.1f} s")
        b.legend(fontsize=8)
    b.set_xlabel("task duration [s, sim time]")
    b.set_ylabel("trials")
    b.set_title("(b) task duration (successes)", fontsize=9)
    fig.tight_layout()
    f12 = out / f"{name}_timing.png"
    fig.savefig(f12, dpi=120)
    plt.close(fig)
    return [
        str(f11.relative_to(REPO)) if f11.is_relative_to(REPO) else str(f11),
        str(f12.relative_to(REPO)) if f12.is_relative_to(REPO) else str(f12),
    ]


def fig10(summary: dict[str, Any], out: Path, name: str) -> str:
    """Fig. 10: where the white box started in each trial (dot: success, cross: failure),
    with the orange box's start (nominal, or each trial's when it moves)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    trials = summary["trial_results"]
    start = np.array([t["layout"]["white_box"][:2] for t in trials])
    ok = np.array([t["success"] for t in trials], dtype=bool)
    box = np.array([t["layout"]["orange_box"][:2] for t in trials])
    fig, ax = plt.subplots(figsize=(5.2, 5.2))
    ax.scatter(box[:, 1], box[:, 0], s=4, c="#f5a04c", alpha=0.3, label="orange box")
    ax.scatter(start[ok, 1], start[ok, 0], s=5, c="#3a9c5b", label=f"success ({ok.sum()})")
    ax.scatter(
        start[~ok, 1],
        start[~ok, 0],
        s=30,
        c="#d62728",
        marker="x",
        label=f"failure ({(~ok).sum()})",
    )
    ax.set_xlabel("y [m] (across the table)")
    ax.set_ylabel("x [m] (away from the robot)")
    ax.invert_xaxis()  # as the robot sees the table from its base
    ax.set_aspect("equal")
    ax.legend(fontsize=7, loc="lower left")
    ax.set_title(
        f"{summary['scene']} ({summary.get('profile', 'ideal')}): "
        f"{100 * summary['success_rate']:.2f} % of {summary['trials']}",
        fontsize=9,
    )
    fig.tight_layout()
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{name}_initial_positions.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return str(path.relative_to(REPO)) if path.is_relative_to(REPO) else str(path)


VARIANTS = ("bench_pick_realistic", "bench_pick_clutter", "bench_pick_moving")
"""Scenes of ``smccli/bench/scenes`` the bench_pick tree also runs in."""
VARIANT_DIR = Path(__file__).resolve().parent / "scenes"


def campaign(name: str, tree: Path, trials: int, **options: Any) -> dict[str, Any]:
    """:func:`~smccli.execute.run_campaign` of ``trials`` on ``tree``, its progress on
    stderr every 25 trials as ``name``; ``options`` are run_campaign's (seed, workers, ...)."""
    t0 = time.perf_counter()

    def on_trial(done: int, ok: int) -> None:
        if done % 25 == 0 or done == trials:
            rate = done / (time.perf_counter() - t0)
            _log(f"{name}: {done}/{trials} trials, {ok} succeeded, {rate:.2f} trials/s")

    return cp.run_campaign(tree, trials=trials, on_trial=on_trial, **options)


def strip_trials(summary: dict[str, Any]) -> dict[str, Any]:
    """The summary without per-trial arrays that bloat the JSON (kept: outcome and distance)."""
    s = dict(summary)
    s["trial_results"] = [
        {k: t[k] for k in ("index", "outcome", "success", "distance", "yaw_distance", "duration")}
        | ({"white_box_xy": t["layout"]["white_box"][:2]} if "white_box" in t["layout"] else {})
        for t in summary["trial_results"]
    ]
    s["failed_trials"] = [
        {k: t[k] for k in ("index", "outcome", "reason", "distance", "path")}
        for t in summary["trial_results"]
        if not t["success"]
    ]
    return s


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="python -m smccli.bench.paper", description=__doc__.split("\n")[0]
    )
    ap.add_argument("--trials", type=int, default=1288, help="bench_pick trials (paper: 1288)")
    ap.add_argument(
        "--panda-trials", type=int, default=300, help="bench_pick_panda trials (0: skip)"
    )
    ap.add_argument(
        "--side-trials",
        type=int,
        default=100,
        help="trials of the pick_place and weigh_sort campaigns (0: skip)",
    )
    ap.add_argument(
        "--variant-trials",
        type=int,
        default=1288,
        help="trials in each of realistic, clutter and moving (0: skip)",
    )
    ap.add_argument("--seed", type=seed_option("paper"), default=0, help="or held-out")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument(
        "--work", type=Path, default=REPO / "bench_results", help="logs and trees (git-ignored)"
    )
    ap.add_argument(
        "--out",
        type=Path,
        help="bench_results.json and img/*.png go here (docs/, or docs/held_out/)",
    )
    return ap


def _save(results: dict[str, Any], path: Path) -> None:
    """Write what is measured so far: a crash later loses no campaign."""
    write_atomic(path, json.dumps(results, indent=1, allow_nan=False) + "\n")


def _bench_pick(args: argparse.Namespace, results: dict[str, Any]) -> list[dict[str, Any]]:
    """Steps 1-2 into ``results``: bench_pick's tree, ranges, latency, match time, its
    campaign, figures and targets. Returns the campaign's distance bands that had trials."""
    _log("compiling bench_pick's demonstration")
    tree_path = demo_tree("bench_pick", args.work)
    tree, scene = resolve(tree_path, None)
    results["ranges"] = check_ranges(scene, "white_box")
    if not results["ranges"]["covers_paper_setup"]:
        _log(f"warning: white_box ranges do not cover the paper's set-up: {results['ranges']}")
    results["latency_serial_ms"] = serial_latency(tree, scene)
    results["match_1000_edges"] = match_1000(tree, scene)
    _log(f"latency {results['latency_serial_ms']}, match {results['match_1000_edges']}")

    summary = campaign("bench_pick", tree_path, args.trials, seed=args.seed, workers=args.workers)
    summary["profile"] = scene.noise.profile
    results["figures"] = [
        *plots(summary, args.out / "img"),
        fig10(summary, args.out / "img", "bench"),
    ]
    results["bench_pick"] = strip_trials(summary)
    bands = [b for b in summary["by_band"] if b["trials"]]
    results["targets"] = {
        "success_rate>=0.99": summary["success_rate"] >= 0.99,
        "every_band>=0.97": all(b["success_rate"] >= 0.97 for b in bands),
        "paper_success_rate": 0.91382,
        "latency_p50<100ms": results["latency_serial_ms"]["p50"] < 100,
        "match_1000<1ms": results["match_1000_edges"]["vectorised_ms_p50"] < 1.0,
    }
    return bands


def _variants(args: argparse.Namespace, results: dict[str, Any], results_file: Path) -> None:
    """Step 5 into ``results``: the realistic demonstration's tree in each variant scene."""
    noisy_tree = noisy_demo_tree(args.work)
    for variant in VARIANTS:
        scene_file = VARIANT_DIR / variant / "scene.yaml"
        _log(f"{variant}: the tree of the realistic demonstration in {scene_file}")
        s = campaign(
            variant,
            noisy_tree,
            args.variant_trials,
            scene=scene_file,
            seed=args.seed,
            workers=args.workers,
        )
        s["profile"] = resolve(noisy_tree, scene_file)[1].noise.profile
        results["figures"] += plots(s, args.out / "img", variant)
        results["figures"].append(fig10(s, args.out / "img", variant))
        results[variant] = strip_trials(s)
        vb = [b for b in s["by_band"] if b["trials"]]
        results["targets"][f"{variant}>=0.99"] = s["success_rate"] >= 0.99
        results["targets"][f"{variant}_every_band>=0.97"] = all(
            b["success_rate"] >= 0.97 for b in vb
        )
        _save(results, results_file)


def _other_campaigns(args: argparse.Namespace, results: dict[str, Any], results_file: Path) -> None:
    """Steps 3-4 into ``results``: each scene's own sample demonstrations and campaign."""
    others = [("bench_pick_panda", args.panda_trials)]
    others += [(name, args.side_trials) for name in ("pick_place", "weigh_sort")]
    for scene_name, trials in others:
        if trials <= 0:
            continue
        _log(f"compiling {scene_name}'s demonstrations")
        tree = demo_tree(scene_name, args.work)
        s = campaign(scene_name, tree, trials, seed=args.seed, workers=args.workers)
        s["profile"] = load_scene(scene_name).noise.profile
        if scene_name == "bench_pick_panda":
            results["figures"] += plots(s, args.out / "img", "bench_panda")
        results[scene_name] = strip_trials(s)
        results["targets"][f"{scene_name}>=0.99"] = s["success_rate"] >= 0.99
        _save(results, results_file)


def _print_results(
    results: dict[str, Any], bands: list[dict[str, Any]], workers: int, results_file: Path
) -> None:
    b = results["bench_pick"]
    print(
        f"bench_pick: {b['successes']}/{b['trials']} = {100 * b['success_rate']:.2f} % "
        f"(95 % CI {100 * b['ci95'][0]:.1f}-{100 * b['ci95'][1]:.1f}), "
        f"{b['trials_per_second']:.2f} trials/s with {workers} workers"
    )
    for band in bands:
        print(f"  {band['label']:>12}: {band['successes']}/{band['trials']}")
    print(
        f"decision latency p50 {results['latency_serial_ms']['p50']:.1f} ms (serial), "
        f"match at 1000 edges {results['match_1000_edges']['vectorised_ms_p50']:.3f} ms"
    )
    for scene_name in (*VARIANTS, "bench_pick_panda", "pick_place", "weigh_sort"):
        if scene_name in results:
            s = results[scene_name]
            print(campaign_line(f"{scene_name} ({s.get('profile', 'ideal')})", s))
    print(f"wrote {results_file}")


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    args.out = args.out or results_dir(args.seed)
    results_file = args.out / "bench_results.json"
    check_output(results_file, force=True)  # before an hour of trials
    results: dict[str, Any] = {
        "command": "python -m smccli.bench.paper "
        + " ".join(argv if argv is not None else sys.argv[1:]),
        "machine": machine(),
    }
    bands = _bench_pick(args, results)
    _save(results, results_file)
    if args.variant_trials > 0:
        _variants(args, results, results_file)
    _other_campaigns(args, results, results_file)
    results["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S")
    _save(results, results_file)
    _print_results(results, bands, args.workers, results_file)
    return 0


if __name__ == "__main__":
    sys.exit(main())
