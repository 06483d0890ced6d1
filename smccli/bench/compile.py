"""Benchmark of ``smc compile``: time and peak memory at 1, 10 and 100 demonstrations,
perception separability (D_P of each object against itself and the others) and action
separability (D_A of one action demonstrated from many layouts, and against other actions).

    python -m smccli.bench.compile [--sizes 1 10 100] [--workers N] [--poses 100]
                                   [--other-layouts 20] [--skip-separability]

Demonstrations are bench_pick's sample script recorded with seeds 0, 1, 2, ..., each from
its own random layout (``--randomize``: the white box anywhere on its 0.25 m x 0.5 m at any
yaw; operator tremor, hesitation and speed differ too), cached under ``out/bench/demos``.
Each compile runs in a fresh process so its peak RSS is its own (the parent's: worker
processes, ``--workers``, default one per core, are not counted) and it pays its imports
and the start of its workers; the load average before it is recorded, as the machine may
be shared. ``--skip-separability`` times the compile only and keeps the separability
figures of the file it rewrites (saying from which run they are).
Separability renders every movable object of the built-in scenes at ``--poses`` random
poses (the scene's ranges, any yaw) with the real camera and perception; the object's
cluster is identified by the layout (evaluation only). Results: ``docs/bench_compile.json``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from smccli.bench.meta import machine
from smccli.outputs import write_atomic

ROOT = Path(__file__).resolve().parents[2]
CACHE = ROOT / "out" / "bench" / "demos"

_CHILD = """
import resource, sys, time, json
t_start = time.perf_counter()
from pathlib import Path
from smccli.learn.compile import compile_logs
workers = None if sys.argv[2] == "default" else int(sys.argv[2])
logs = [Path(p) for p in sys.argv[3:]]
t0 = time.perf_counter()
r = compile_logs(logs, Path(sys.argv[1]), rebuild=True, workers=workers)
dt = time.perf_counter() - t0
# VmHWM, not ru_maxrss: Linux carries ru_maxrss over execve, so a child started by a big
# parent (one that has just recorded the demos) reported the parent's peak (429 MB).
hwm = [ln for ln in open("/proc/self/status") if ln.startswith("VmHWM:")]
kb = int(hwm[0].split()[1]) if hwm else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
rss_mb = kb / 1024
print(json.dumps({"seconds": dt, "with_imports_s": time.perf_counter() - t_start,
                  "peak_rss_mb": rss_mb, "nodes": len(r.tree.nodes), "edges": len(r.tree.edges)}))
"""


def demos(
    n: int, scene: str = "bench_pick", script: str | Path = "demo.yaml", first_seed: int = 0
) -> list[Path]:
    """``n`` recordings of a script, each from its own random layout (``--randomize``) with
    seeds ``first_seed``.. (cached). A relative ``script`` is a sample script of ``scene``."""
    from smccli.logs import read_log
    from smccli.record.session import RecordConfig, record

    CACHE.mkdir(parents=True, exist_ok=True)
    script = Path(script)
    path_of = script if script.is_absolute() else ROOT / "sample_logs" / scene / script
    out = []
    for seed in range(first_seed, first_seed + n):
        path = CACHE / f"{scene}_{script.stem}_r{seed}.mcap"
        if path.exists() and read_log(path, topics=()).interrupted:
            path.unlink()  # a benchmark stopped mid-recording: record it again
        if not path.exists():
            record(
                RecordConfig(
                    scene=scene,
                    script=path_of,
                    seed=seed,
                    output=path,
                    randomize=True,
                    reproducible=True,
                )
            )
        out.append(path)
    return out


# Actions of bench_pick that share a gripper event and a salient object with the sample
# demonstration's but are other actions: another goal on the object, or another way of
# coming to it. D_A must tell them from the demonstration's, whatever the layout.
_GRASP = "  - gripper: close\n  - mark: grasp\n"
_PLACE = "  - gripper: open\n  - mark: release\n"
_LIFT = "  - move_to: {object: white_box, offset: [0, 0, 0.15]}\n"
OTHER_ACTIONS: dict[str, tuple[int, str]] = {
    "grasp 4 cm off centre": (
        0,
        "  - move_to: {object: white_box, offset: [0.04, 0, 0.12]}\n"
        "  - move_to: {object: white_box, offset: [0.04, 0, 0.0]}\n" + _GRASP,
    ),
    "grasp coming from the side": (
        0,
        "  - move_to: {object: white_box, offset: [0, 0.12, 0.03]}\n"
        "  - move_to: {object: white_box, offset: [0, 0, 0.0]}\n" + _GRASP,
    ),
    "place in a corner": (
        1,
        "  - move_to: {object: white_box, offset: [0, 0, 0.0]}\n"
        + _GRASP
        + _LIFT
        + "  - move_to: {object: orange_box, offset: [0.07, 0.03, 0.17]}\n"
        "  - move_to: {object: orange_box, offset: [0.07, 0.03, 0.04]}\n" + _PLACE,
    ),
    "place coming from the side": (
        1,
        "  - move_to: {object: white_box, offset: [0, 0, 0.0]}\n"
        + _GRASP
        + _LIFT
        + "  - move_to: {object: orange_box, offset: [-0.2, 0, 0.06]}\n"
        "  - move_to: {object: orange_box, offset: [0, 0, 0.04]}\n" + _PLACE,
    ),
}
"""Name -> (index of the demonstration's fragment it is compared with, teleop steps)."""


def _chains(logs: list[Path]) -> list:
    from smccli.learn.chain import extract_chain
    from smccli.learn.params import SmcParams
    from smccli.learn.segmentation import SegmentMode
    from smccli.logs import read_log
    from smccli.logs.topics import READ_TOPICS

    return [
        extract_chain(read_log(p, topics=READ_TOPICS), SmcParams(), SegmentMode.markers)
        for p in logs
    ]


def action_separability(n_layouts: int, n_other: int) -> dict:
    """D_A between the same action demonstrated from ``n_layouts`` random layouts, and
    between it and other actions (``OTHER_ACTIONS``, ``n_other`` layouts each) [m]."""
    from smccli.learn.contingency import d_a
    from smccli.learn.params import SmcParams

    params = SmcParams()
    same_chains = _chains(demos(n_layouts))
    header = (ROOT / "sample_logs" / "bench_pick" / "demo.yaml").read_text().split("steps:")[0]
    out: dict[str, dict] = {}
    for k, name in enumerate(("grasp", "place")):
        acts = [c.smcs[k].action for c in same_chains]
        d = [d_a(a, b, params) for a, b in itertools.combinations(acts, 2)]
        out[name] = {"layouts": len(acts), "same_p99": float(np.percentile(d, 99))}
        out[name]["same_max"] = float(np.max(d))
    scripts = CACHE / "scripts"
    scripts.mkdir(parents=True, exist_ok=True)
    for i, (other, (k, steps)) in enumerate(OTHER_ACTIONS.items()):
        script = scripts / f"other{i}.yaml"
        text = header + "steps:\n" + steps
        if not script.exists() or script.read_text() != text:
            script.write_text(text)
        chains = _chains(demos(n_other, script=script, first_seed=1000))
        mine = [c.smcs[k].action for c in chains]
        base = [c.smcs[k].action for c in same_chains[:n_other]]
        d = [d_a(a, b, params) for a in mine for b in base]
        out[other] = {
            "compared_with": ("grasp", "place")[k],
            "layouts": len(mine),
            "different_p1": float(np.percentile(d, 1)),
            "different_min": float(np.min(d)),
        }
    same_p99 = max(out[n]["same_p99"] for n in ("grasp", "place"))
    diff_p1 = min(v["different_p1"] for n, v in out.items() if n not in ("grasp", "place"))
    summary = {"t_ha": params.t_ha, "same_p99": same_p99, "different_p1": diff_p1, "by_action": out}
    print(
        f"action separability ({n_layouts} layouts, {n_other} per other action): same action "
        f"p99 {same_p99:.4f} m, other actions p1 {diff_p1:.4f} m; T_hA = {params.t_ha} m"
    )
    for name, v in out.items():
        print(f"  {name:28s} {json.dumps({k: v[k] for k in v if k != 'compared_with'})}")
    return summary


def compile_scaling(sizes: list[int], workers: int | None = None) -> list[dict]:
    """``compile_logs`` of the first n demos for each n of ``sizes`` (``workers``: its
    default if None), each in a fresh process: wall time of the call and with the imports."""
    from smccli.learn.compile import default_workers

    logs = demos(max(sizes))
    rows = []
    for n in sizes:
        tree = CACHE.parent / f"tree_{n}.json"
        load = os.getloadavg()[0]
        proc = subprocess.run(
            [sys.executable, "-c", _CHILD, str(tree), str(workers or "default")]
            + [str(p) for p in logs[:n]],
            capture_output=True,
            text=True,
            check=True,
        )
        row = json.loads(proc.stdout.strip().splitlines()[-1])
        row.update(
            demos=n,
            workers=workers or default_workers(n),
            seconds_per_demo=row["seconds"] / n,
            load_before=round(load, 2),
        )
        rows.append(row)
        print(
            f"compile {n:4d} demos, {row['workers']} workers: {row['seconds']:7.2f} s "
            f"({row['seconds_per_demo']:.2f} s/demo; {row['with_imports_s']:.2f} s with the "
            f"imports), peak RSS {row['peak_rss_mb']:.0f} MB, tree {row['nodes']} nodes "
            f"{row['edges']} edges, load before {load:.2f}"
        )
    return rows


def separability(n_poses: int, seed: int = 0) -> dict:
    """D_P (cluster part) same-object vs different-object percentiles over random poses."""
    from smccli.perception import PerceptionParams, clusters_from_frame, d_cluster
    from smccli.world.layout import sample_layout
    from smccli.world.scene import load_scene
    from smccli.world.sim import Sim

    params = PerceptionParams()
    rng = np.random.default_rng(seed)
    seen: dict[str, list] = {}
    for scene_name in ("pick_place", "weigh_sort", "bench_pick"):
        scene = load_scene(scene_name)
        movable = [o.name for o in scene.objects if not o.fixed and o.range_x[0] < o.range_x[1]]
        sim = Sim(scene)
        variants: list[str | None] = [v for v, _ in scene.variants] or [None]
        for i in range(n_poses * len(variants)):
            variant = variants[i % len(variants)]
            layout = sample_layout(scene, rng, variant=variant)
            sim.reset(layout)
            clusters = clusters_from_frame(sim.render_camera(), sim.robot_geometry(), params)
            for name in movable:
                if name not in layout:
                    continue
                x, y = layout[name][:2]
                near = [
                    c for c in clusters if np.hypot(c.centroid[0] - x, c.centroid[1] - y) < 0.03
                ]
                if len(near) == 1:
                    seen.setdefault(f"{scene_name}/{name}", []).append(near[0])
        sim.close()
    # The two weigh_sort boxes look alike by design (only the scale tells them apart).
    alike = {frozenset({"weigh_sort/light_box", "weigh_sort/heavy_box"})}
    same, diff, per_object = [], [], {}
    names = sorted(seen)
    for name in names:
        cs = seen[name][:n_poses]
        d = [d_cluster(a, b, params) for a, b in itertools.combinations(cs, 2)]
        same += d
        per_object[name] = {"poses": len(cs), "p99_same": float(np.percentile(d, 99))}
    for a, b in itertools.combinations(names, 2):
        if frozenset({a, b}) in alike:
            continue
        ca, cb = seen[a][:30], seen[b][:30]
        d = [d_cluster(x, y, params) for x in ca for y in cb]
        diff += d
        per_object[a].setdefault("min_other", 1e9)
        per_object[a]["min_other"] = min(per_object[a]["min_other"], float(np.min(d)))
    out = {
        "poses_per_object": n_poses,
        "same_p99": float(np.percentile(same, 99)),
        "same_max": float(np.max(same)),
        "different_p1": float(np.percentile(diff, 1)),
        "different_min": float(np.min(diff)),
        "t_hp": 0.1,
        "objects": per_object,
    }
    print(
        f"separability over {n_poses} poses/object: same-object p99 {out['same_p99']:.3f} "
        f"(max {out['same_max']:.3f}), different-object p1 {out['different_p1']:.3f} "
        f"(min {out['different_min']:.3f}); T_hP = 0.1"
    )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", type=int, nargs="+", default=[1, 10, 100])
    ap.add_argument("--poses", type=int, default=100)
    ap.add_argument("--other-layouts", type=int, default=20)
    ap.add_argument(
        "--workers", type=int, help="compile's worker processes (default: one per core)"
    )
    ap.add_argument(
        "--skip-separability",
        action="store_true",
        help="time the compile only; keep the separability figures of the existing file",
    )
    args = ap.parse_args()
    t0 = time.perf_counter()
    out = ROOT / "docs" / "bench_compile.json"
    doc: dict[str, object] = {
        "command": "python -m smccli.bench.compile " + " ".join(sys.argv[1:]),
        "machine": machine(),
        "compile": compile_scaling(args.sizes, args.workers),
    }
    if args.skip_separability:
        old = json.loads(out.read_text()) if out.exists() else {}
        kept = [k for k in ("separability", "action_separability") if k in old]
        doc.update({k: old[k] for k in kept})
        if kept:  # the run that measured them, however many compile-only runs ago
            doc["separability_from"] = old.get("separability_from") or {
                "command": old.get("command"),
                "commit": old.get("machine", {}).get("commit"),
                "started": old.get("machine", {}).get("started"),
            }
    else:
        doc["separability"] = separability(args.poses)
        doc["action_separability"] = action_separability(max(args.sizes), args.other_layouts)
    doc["wall_s"] = round(time.perf_counter() - t0, 1)
    write_atomic(out, json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
