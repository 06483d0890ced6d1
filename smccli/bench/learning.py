"""Learning curve: success against the number of demonstrations merged (issue 27, part 4).

``python -m smccli.bench.learning [--demos 1 2 4 8] [--trials 300] [--workers 2]``

The paper teaches from one demonstration; users give a few, each from another layout, each
clumsy in its own way. Here :data:`DEMOS` human-like demonstrations of bench_pick
(:func:`clumsy_script`: each its own tremor, hesitations, speed, a wandering approach
through a detour of its own, a grasp off the box's centre and off its axis) are recorded
from their own random layouts through the realistic sensors, in a scene with achromatic
look-alikes of the white box (``scenes/bench_pick_lookalike``). The trees of the first 1,
2, 4 and 8 of them run one campaign each on the same seed (the same layouts); the seed
also draws the operators (``--seed S``: operators S to S + 7). Writes
``docs/bench_learning.json`` and ``docs/img/bench_learning.png`` (success with Wilson 95 %
intervals), and first the margin the look-alikes leave: D_P of the white box against
itself and against each of them over random layouts (:func:`lookalike_separability`).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from smccli.bench.meta import campaign_line, campaign_row, machine, write_rows
from smccli.bench.paper import VARIANT_DIR, campaign, strip_trials
from smccli.bench.seeds import results_dir, seed_option

REPO = Path(__file__).resolve().parents[2]
SCENE = VARIANT_DIR / "bench_pick_lookalike" / "scene.yaml"
DEMOS = 8
"""Demonstrations recorded; the curve merges the first 1, 2, 4, 8 of them."""


def clumsy_script(k: int) -> str:
    """Teleop script of the ``k``-th clumsy operator (deterministic in ``k``): the sample
    task with a tremor of 2-4 mm, hesitations of 0.3-0.8 s, 0.08-0.15 m/s, a detour of up
    to 8 cm above the box before the descent, a grasp up to 1.5 cm off the box's centre
    along it and 0.1 rad off its axis, and a release up to 3 cm off the orange box's centre."""
    r = np.random.default_rng([27, k])
    u = lambda lo, hi: float(r.uniform(lo, hi))  # noqa: E731
    detour = [u(-0.08, 0.08), u(-0.08, 0.08), u(0.15, 0.22)]
    along, yaw = u(-0.015, 0.015), u(-0.1, 0.1)
    release = [u(-0.03, 0.03), u(-0.02, 0.02)]

    def v(xs: list[float]) -> str:
        return "[" + ", ".join(f"{x:.3f}" for x in xs) + "]"

    return f"""# Clumsy operator {k} (smccli/bench/learning.py).
scene: bench_pick_lookalike
description: "White box into the orange box, by a clumsy hand ({k})"
speed: {u(0.08, 0.15):.3f}
tremor: {u(0.002, 0.004):.4f}
hesitation: {u(0.3, 0.8):.2f}
speed_variation: 0.25
steps:
  - move_to: {{object: white_box, offset: {v(detour)}}}
  - move_to: {{object: white_box, offset: {v([along, 0, 0.10])}, yaw: {yaw:.3f}}}
  - move_to: {{object: white_box, offset: {v([along, 0, 0.0])}, yaw: {yaw:.3f}}}
  - gripper: close
  - mark: grasp
  - move_to: {{object: white_box, offset: [0, 0, 0.15]}}
  - move_to: {{object: orange_box, offset: {v([*release, 0.17])}}}
  - move_to: {{object: orange_box, offset: {v([*release, 0.04])}}}
  - gripper: open
  - mark: release
  - move_to: {{object: orange_box, offset: [0, 0, 0.2]}}
"""


def record_demos(work: Path, n: int, first: int = 0) -> list[Path]:
    """The ``n`` clumsy demonstrations of operators ``first`` ... ``first + n - 1``, operator
    ``k`` from random layout ``k``; a demonstration that fails its task (the recorder's
    verdict) is recorded again with the layout 1000 further on, as a person would redo it."""
    from smccli.logs import read_log
    from smccli.record.session import RecordConfig, record

    logs = []
    for k in range(first, first + n):
        script = work / f"clumsy_{k}.yaml"
        script.write_text(clumsy_script(k))
        for attempt in range(5):
            log = work / f"clumsy_{k}_{attempt}.mcap"
            seed = 1000 * attempt + k
            record(
                RecordConfig(scene=str(SCENE), script=script, output=log, seed=seed, randomize=True)
            )
            task = read_log(log, topics=()).task or {}
            if task.get("success"):
                logs.append(log)
                break
        else:
            raise RuntimeError(f"clumsy operator {k} failed the task five times")
    return logs


def merged_trees(
    logs: Sequence[Path], demos: Sequence[int], work: Path
) -> Iterator[tuple[int, Path]]:
    """``(n, tree)`` for each ``n`` of ``demos``: the first ``n`` of ``logs`` compiled into a
    new tree in ``work`` (the curve's points)."""
    from smccli.learn.compile import compile_logs

    for n in demos:
        tree = work / f"tree_{n}.json"
        compile_logs(list(logs[:n]), tree, rebuild=True)
        yield n, tree


def lookalike_separability(n_layouts: int, seed: int = 5) -> dict[str, Any]:
    """D_P (cluster part) of the white box against itself and against each look-alike over
    ``n_layouts`` random layouts of the scene, each through its own draw of the realistic
    sensors (exposure, white balance, noise): the margin part 1 of issue 27 is about. The
    layout's truth only pairs each cluster with its object (evaluation's side)."""
    import itertools

    from smccli.perception import clusters_from_frame, d_cluster
    from smccli.perception.params import scene_perception
    from smccli.world.layout import sample_layout
    from smccli.world.scene import load_scene
    from smccli.world.sim import Sim

    scene = load_scene(SCENE)
    params = scene_perception(scene)
    rng = np.random.default_rng(seed)
    seen: dict[str, list[Any]] = {"white_box": [], "grey_bar": [], "cream_box": []}
    sim = None
    for i in range(n_layouts):
        layout = sample_layout(scene, rng)
        sim = sim or Sim(scene, layout)
        sim.reset(layout, noise_seed=i)
        clusters = clusters_from_frame(sim.render_camera(), sim.robot_geometry(), params)
        for name, found in seen.items():
            xy = np.array(layout[name][:2])
            near = [c for c in clusters if np.hypot(*(c.centroid[:2] - xy)) < 0.03]
            if len(near) == 1:
                found.append(near[0])
    if sim is not None:
        sim.close()
    white = seen["white_box"]
    same = [d_cluster(a, b, params) for a, b in itertools.combinations(white, 2)]
    out: dict[str, Any] = {
        "layouts": n_layouts,
        "white_box_views": len(white),
        "same_max": max(same),
        "same_p99": float(np.percentile(same, 99)),
    }
    for other in ("grey_bar", "cream_box"):
        d = [d_cluster(a, b, params) for a in white for b in seen[other]]
        out[other] = {"views": len(seen[other]), "min": min(d), "p1": float(np.percentile(d, 1))}
    return out


def figure(rows: list[dict[str, Any]], out: Path) -> str:
    """Success [%] against demonstrations merged, with Wilson 95 % intervals."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["demonstrations"] for r in rows]
    rate = np.array([100 * r["success_rate"] for r in rows])
    lo = np.array([100 * r["ci95"][0] for r in rows])
    hi = np.array([100 * r["ci95"][1] for r in rows])
    fig, ax = plt.subplots(figsize=(5.5, 3.4))
    ax.errorbar(n, rate, yerr=[rate - lo, hi - rate], marker="o", capsize=4)
    ax.set_xscale("log", base=2)
    ax.set_xticks(n, [str(x) for x in n])
    ax.set_xlabel("demonstrations merged (clumsy, each from its own layout)")
    ax.set_ylabel("success [%]")
    ax.set_ylim(min(50.0, float(lo.min()) - 5), 101)
    ax.axhline(99, color="grey", lw=0.8, ls="--")
    ax.set_title(f"bench_pick, realistic sensors, look-alikes ({rows[0]['trials']} trials each)")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return str(out)


def _shown(path: Path) -> str:
    """``path`` from the repository's top when it lies inside it, else as it is."""
    path = path.resolve()
    return str(path.relative_to(REPO)) if path.is_relative_to(REPO) else str(path)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--demos", type=int, nargs="+", default=[1, 2, 4, 8])
    ap.add_argument("--trials", type=int, default=300)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=seed_option("learning"), default=0, help="or held-out")
    ap.add_argument("--separability-layouts", type=int, default=30)
    ap.add_argument("--out", type=Path, help="docs/bench_learning.json, or docs/held_out/...")
    ap.add_argument("--fig", type=Path, help="docs/img/bench_learning.png, or docs/held_out/...")
    args = ap.parse_args(argv)
    args.out = args.out or results_dir(args.seed) / "bench_learning.json"
    args.fig = args.fig or results_dir(args.seed) / "img" / "bench_learning.png"
    meta = machine()
    sep = lookalike_separability(args.separability_layouts)
    print(
        f"D_P white box to itself: max {sep['same_max']:.3f}; to the grey bar: min "
        f"{sep['grey_bar']['min']:.3f}; to the cream box: min {sep['cream_box']['min']:.3f}",
        flush=True,
    )
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        logs = record_demos(work, max(args.demos), first=args.seed)
        for n, tree in merged_trees(logs, args.demos, work):
            s = campaign(f"{n} demo(s)", tree, args.trials, seed=args.seed, workers=args.workers)
            print(campaign_line(f"{n} demonstration(s)", s), flush=True)
            rows.append(
                campaign_row(
                    s,
                    demonstrations=n,
                    success_rate=s["success_rate"],
                    ci95=s["ci95"],
                    failures={k: v for k, v in s["failures"].items() if v},
                    failed_trials=strip_trials(s)["failed_trials"],
                )
            )
        scripts = [clumsy_script(args.seed + k) for k in range(max(args.demos))]
        redone = [p.name for p in logs if not p.stem.endswith("_0")]
    write_rows(
        args.out,
        "smccli.bench.learning",
        argv,
        meta,
        rows,
        scene=str(SCENE.relative_to(REPO)),
        scripts=scripts,
        redone=redone,
        separability=sep,
        figure=_shown(Path(figure(rows, args.fig))),
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
