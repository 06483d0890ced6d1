"""A family of look-alikes of the white box, one drawn per trial: ``python -m
smccli.bench.lookalike [--trials 300] [--seed S] [--workers 2]``.

Issue 38, part 2. The learning curve's scene (``scenes/bench_pick_lookalike``) holds one
fixed grey bar; a user's scene with another grey block, on a seed nobody tuned on, made
96/100. Here one clumsy demonstration (operator ``S``, :func:`~smccli.bench.learning.
record_demos`) is recorded and compiled in that scene, and every trial ``i`` replaces the
grey bar by a look-alike drawn from ``[S, i]`` (:func:`draw_trial`, the same on any number
of workers):

- *colour*: an achromatic grey ``g`` uniform in :data:`GREY` (the white box is 0.95), or in
  :data:`NEAR_COLOUR_SHARE` of the trials a near-colour between the creams and off-whites of
  :data:`NEAR_COLOURS` (linear between them);
- *size*: the white box's times a factor uniform in :data:`SIZE_FACTOR`, drawn per axis;
- *pose*: yaw uniform; in :data:`TOUCH_SHARE` of the trials touching the white box (edge to
  edge gap 0-20 µm), in :data:`NEAR_SHARE` at a gap uniform in 0-3 cm, in the rest anywhere
  in :data:`AREA` (the white box's range and beyond). Only real overlap of the footprints
  (oriented rectangles, a cylinder's circumscribed 16-gon) is rejected, with the white box
  and with every other object, whose poses are the learning campaign's (``[S, i]``).

Each trial runs in a scene file of its own (the learning scene's, the look-alike's colour
and size written in and its range zero), through :func:`~smccli.execute.episode.episode`,
judged by the episode's own result. For evaluation only (the simulator's truth, never
control's), the first camera frame as the robot sees it (realistic noise) and MuJoCo's
segmentation give each object's mean colour (its darker half: the sides) over the table's
around it, channel by channel (:func:`appearance`): gain and white balance cancel. A
look-alike is *indistinguishable* when every channel lies as close to the white box's as
a second white box's lies in 95 % of :data:`CALIBRATION_LAYOUTS` frames (:func:`calibrate`:
the family's draws painted white): in this lamp light a white box clips the sensor, and a
light grey nearly does. Those trials are reported apart and left out of the goal. Writes
``docs/bench_lookalike.json`` (or ``docs/held_out/``): per-trial rows and success by grey
band and by gap band with Wilson 95 % intervals.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import argparse  # noqa: E402
import functools  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from smccli.bench.learning import SCENE, record_demos  # noqa: E402
from smccli.bench.meta import machine, write_rows  # noqa: E402
from smccli.bench.seeds import results_dir, seed_option  # noqa: E402
from smccli.execute.campaign import wilson  # noqa: E402
from smccli.world.scene import Layout, Scene  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
TARGET = "white_box"
REPLACED = "grey_bar"
"""The learning scene's fixed look-alike, which the drawn one replaces."""
LOOKALIKE = "lookalike"
GREY = (0.35, 0.70)
"""An achromatic look-alike's grey level, drawn uniformly (the white box: 0.95)."""
NEAR_COLOURS = ((0.93, 0.88, 0.75), (0.90, 0.90, 0.85))
"""The ends of the near-colours (a cream, an off-white): drawn on the line between."""
NEAR_COLOUR_SHARE = 0.2
SIZE_FACTOR = (0.8, 1.2)
"""The factor of the white box's size, drawn per axis."""
TOUCH_SHARE = 0.15
"""Share of the trials whose look-alike touches the white box."""
NEAR_SHARE = 0.35
"""Share of the trials whose look-alike stands 0 to :data:`NEAR_GAP` from it."""
NEAR_GAP = 0.03
"""Largest edge-to-edge gap of a *near* placement [m]."""
AREA = ((0.25, 0.75), (-0.45, 0.45))
"""Where the look-alike's centre may be (x, y) [m]: the camera's work area on the table."""
DRAW_STREAM = 38
"""Third word of the look-alike's generator ``[S, i, 38]`` (the layout's is ``[S, i]``)."""
RING_PX = (3, 12)
"""The table ring around an object in :func:`appearance`: from 3 to 12 pixels out."""
CALIBRATION_SEED = 1
"""A development seed: the twins of :func:`calibrate` are the family's draws of ``[1, k]``."""
CALIBRATION_LAYOUTS = 40
GREY_BANDS = ((0.35, 0.45), (0.45, 0.55), (0.55, 0.65), (0.65, 0.70))
GAP_BANDS = (
    ("touching <1 cm", 0.0, 0.01),
    ("1-3 cm", 0.01, 0.03),
    ("3-10 cm", 0.03, 0.10),
    (">10 cm", 0.10, math.inf),
)
"""Bands of the look-alike's edge-to-edge gap to the white box [m]."""


# --- footprints --------------------------------------------------------------------------


def footprint(shape: str, size: Sequence[float], pose: Sequence[float]) -> np.ndarray:
    """The object's footprint on the table as a convex polygon, shape (k, 2) [m]: a box's
    (or an open box's) rectangle, a cylinder's circumscribed 16-gon (0.6 mm wider than a
    6 cm cylinder at most)."""
    x, y, _, yaw = pose
    if shape == "cylinder":
        n = 16
        r = size[0] / 2 / math.cos(math.pi / n)
        a = np.arange(n) * 2 * math.pi / n
        local = r * np.stack([np.cos(a), np.sin(a)], axis=1)
    else:
        hx, hy = size[0] / 2, size[1] / 2
        local = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
    c, s = math.cos(yaw), math.sin(yaw)
    return local @ np.array([[c, s], [-s, c]]) + np.array([x, y])


def polygon_gap(a: np.ndarray, b: np.ndarray) -> float:
    """Edge-to-edge distance of convex polygons ``a``, ``b`` (k, 2) [m]; when they overlap,
    minus the smallest depth along an edge normal (separating axes). Hand-written: OpenCV's
    rotated-rectangle intersection is float32 and gives no distance (touching is 0 here)."""
    sep = -math.inf
    for p in (a, b):
        e = np.roll(p, -1, axis=0) - p
        n = np.stack([e[:, 1], -e[:, 0]], axis=1) / np.hypot(e[:, 0], e[:, 1])[:, None]
        pa, pb = a @ n.T, b @ n.T
        sep = max(sep, float(np.maximum(pa.min(0) - pb.max(0), pb.min(0) - pa.max(0)).max()))
    if sep <= 0:
        return sep
    return min(_to_edges(a, b), _to_edges(b, a))


def _to_edges(points: np.ndarray, poly: np.ndarray) -> float:
    """Smallest distance from ``points`` to the edges of ``poly`` [m]."""
    d = np.roll(poly, -1, axis=0) - poly
    rel = points[:, None, :] - poly[None, :, :]
    t = np.clip((rel * d[None]).sum(-1) / (d * d).sum(-1)[None], 0.0, 1.0)
    return float(np.linalg.norm(rel - t[..., None] * d[None], axis=-1).min())


# --- the draw -----------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Draw:
    """Trial ``index``'s look-alike and the other objects' layout."""

    index: int
    kind: str
    """``grey`` or ``near-colour``."""
    rgb: tuple[float, float, float]
    factor: tuple[float, float, float]
    """Size factors along x, y, z of the white box's size."""
    size: tuple[float, float, float]
    """Full extents [m]."""
    placement: str
    """``touching``, ``near`` (0-3 cm) or ``anywhere``."""
    pose: tuple[float, float, float, float]
    """x, y, z, yaw [m, m, m, rad]."""
    gap: float
    """Edge-to-edge gap of the footprints to the white box's [m]."""
    layout: Layout
    """The other objects: the learning campaign's layout of ``[S, i]``, its grey bar out."""


def draw_trial(scene: Scene, seed: int, index: int) -> Draw:
    """Trial ``index`` of the campaign with ``seed`` in the learning ``scene``: the layout
    of :func:`~smccli.execute.episode.layout_for` without the grey bar, and a look-alike
    from ``default_rng([seed, index, DRAW_STREAM])``."""
    from smccli.execute.episode import layout_for

    layout = dict(layout_for(scene, seed, index))
    layout.pop(REPLACED, None)
    rng = np.random.default_rng([seed, index, DRAW_STREAM])
    if rng.random() < NEAR_COLOUR_SHARE:
        kind, t = "near-colour", float(rng.random())
        a, b = (np.array(c) for c in NEAR_COLOURS)
        rgb = tuple(float(v) for v in (1 - t) * a + t * b)
    else:
        kind, g = "grey", float(rng.uniform(*GREY))
        rgb = (g, g, g)
    factor = tuple(float(f) for f in rng.uniform(*SIZE_FACTOR, size=3))
    size = tuple(s * f for s, f in zip(scene.object(TARGET).size, factor, strict=True))
    u = rng.random()
    placement = (
        "touching" if u < TOUCH_SHARE else "near" if u < TOUCH_SHARE + NEAR_SHARE else "anywhere"
    )
    pose, gap = _place(rng, scene, layout, size, placement)
    return Draw(
        index=index,
        kind=kind,
        rgb=rgb,  # type: ignore[arg-type]
        factor=factor,  # type: ignore[arg-type]
        size=size,  # type: ignore[arg-type]
        placement=placement,
        pose=pose,
        gap=gap,
        layout=layout,
    )


def _place(
    rng: np.random.Generator,
    scene: Scene,
    layout: Layout,
    size: Sequence[float],
    placement: str,
    max_tries: int = 1000,
) -> tuple[tuple[float, float, float, float], float]:
    """A pose for the look-alike and its gap to the white box: its centre in :data:`AREA`,
    its footprint overlapping nobody's (touching allowed)."""
    others = {
        name: footprint(scene.object(name).shape, scene.object(name).size, pose)
        for name, pose in layout.items()
    }
    white = others[TARGET]
    wx, wy = layout[TARGET][:2]
    z = size[2] / 2
    for _ in range(max_tries):
        yaw = float(rng.uniform(-math.pi, math.pi))
        if placement == "anywhere":
            x, y = (float(rng.uniform(*r)) for r in AREA)
        else:
            target = 0.0 if placement == "touching" else float(rng.uniform(0.0, NEAR_GAP))
            phi = float(rng.uniform(-math.pi, math.pi))
            u = np.array([math.cos(phi), math.sin(phi)])
            at_white = footprint("box", size, (wx, wy, z, yaw))
            r = _distance_for_gap(white, at_white, u, target)
            x, y = float(wx + r * u[0]), float(wy + r * u[1])
        if not (AREA[0][0] <= x <= AREA[0][1] and AREA[1][0] <= y <= AREA[1][1]):
            continue
        mine = footprint("box", size, (x, y, z, yaw))
        if all(polygon_gap(mine, p) >= 0 for p in others.values()):
            return (x, y, z, yaw), polygon_gap(mine, white)
    raise RuntimeError(f"no free pose for the look-alike in {max_tries} draws")


def _distance_for_gap(fixed: np.ndarray, moved: np.ndarray, u: np.ndarray, target: float) -> float:
    """How far ``moved`` (a polygon overlapping ``fixed``) must go along the unit vector
    ``u`` to stand ``target`` (to +20 µm) from ``fixed`` [m]. The gap grows monotonically
    along a ray from inside the Minkowski difference of two convex shapes, so bisection
    finds it; the result never undershoots."""
    lo, hi = 0.0, 0.5
    while polygon_gap(fixed, moved + hi * u) < target:
        hi *= 2
    while hi - lo > 2e-5:
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if polygon_gap(fixed, moved + mid * u) < target else (lo, mid)
    return hi


# --- the trial's scene ------------------------------------------------------------------


@functools.cache
def learning_scene() -> Scene:
    """The learning curve's scene (its grey bar the one replaced)."""
    from smccli.world.scene import load_scene

    return load_scene(SCENE)


def trial_scene_text(draw: Draw) -> str:
    """The learning scene file with its grey bar replaced by ``draw``'s look-alike (at the
    drawn pose, range zero), its MJCF named by absolute path (the file is written
    elsewhere)."""
    raw = yaml.safe_load(SCENE.read_text())
    raw["mjcf"] = str((SCENE.parent / raw["mjcf"]).resolve())
    raw["description"] = f"bench_pick among look-alikes, trial {draw.index}'s of the family"
    x, y, z, yaw = draw.pose
    for o in raw["objects"]:
        if o["name"] == REPLACED:
            o.update(
                name=LOOKALIKE,
                size=list(draw.size),
                rgba=[*draw.rgb, 1.0],
                pose=[x, y, z, yaw],
                range={"x": [x, x], "y": [y, y], "yaw": [yaw, yaw]},
            )
    return yaml.safe_dump(raw, sort_keys=False)


def trial_scene(draw: Draw, folder: Path) -> Scene:
    """Write ``folder/scene.yaml`` (:func:`trial_scene_text`) and load it."""
    from smccli.world.scene import load_scene

    path = folder / "scene.yaml"
    path.write_text(trial_scene_text(draw))
    return load_scene(path)


# --- what a person sees (evaluation: the simulator's truth) ---------------------------------


def appearance(sim: Any, names: Sequence[str]) -> dict[str, list[float] | None]:
    """Each object's mean colour in the camera frame the robot would take now (its sensor
    noise included) over the table top's around it (a ring :data:`RING_PX` pixels out:
    the lamp lights the table unevenly, and a person, as perception does, judges an object
    against its surroundings), per channel: gain and white balance cancel. The object's
    darker half of pixels (by max(R, G, B)) only: its side faces, where the lamp-lit tops of
    a white box and of a light grey one both clip (smccli/perception/brightness.py). Pixels
    from MuJoCo's segmentation rendering, the object's eroded by one pixel (edges mix
    colours). None for an object or ring of under 10 pixels."""
    import cv2
    import mujoco

    from smccli.world.specs import HIDDEN_GROUP

    frame = sim.render_camera()
    m, cam = sim.model, sim.scene.camera
    renderer = mujoco.Renderer(m, cam.height, cam.width)
    try:
        renderer.enable_segmentation_rendering()
        opt = mujoco.MjvOption()
        opt.geomgroup[:] = 1
        opt.geomgroup[HIDDEN_GROUP] = 0
        renderer.update_scene(sim.data, camera=cam.name, scene_option=opt)
        seg = renderer.render()
    finally:
        renderer.close()
    is_geom = seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM
    geom = np.where(is_geom, seg[..., 0], 0)
    body = np.where(is_geom, m.geom_bodyid[geom], -1)
    table = is_geom & (geom == m.geom("table_top").id)
    rgb = frame.rgb.astype(float)

    def grown(mask: np.ndarray, px: int) -> np.ndarray:
        return cv2.dilate(mask.astype(np.uint8), np.ones((2 * px + 1,) * 2, np.uint8)) > 0

    out: dict[str, list[float] | None] = {}
    for name in names:
        mask = body == m.body(name).id
        inner = ~grown(~mask, 1)  # eroded by one pixel: edges mix colours
        ring = table & grown(mask, RING_PX[1]) & ~grown(mask, RING_PX[0])
        px = rgb[inner]
        side = px[px.max(1) <= np.median(px.max(1))] if len(px) else px
        ok = len(side) >= 10 and ring.sum() >= 10
        out[name] = (side.mean(0) / rgb[ring].mean(0)).tolist() if ok else None
    return out


def calibrate(n: int = CALIBRATION_LAYOUTS) -> dict[str, Any]:
    """How far a second white box's :func:`appearance` lies from the white box's in the
    same frame: ``n`` trials of the family on :data:`CALIBRATION_SEED`, each look-alike
    painted the white box's colour (its drawn size and pose kept). The threshold per
    channel is the 95th percentile of |difference| over those twins."""
    import dataclasses

    from smccli.world.sim import Sim

    white = learning_scene().object(TARGET).rgba[:3]
    diffs = []
    for k in range(n):
        draw = dataclasses.replace(draw_trial(learning_scene(), CALIBRATION_SEED, k), rgb=white)
        with tempfile.TemporaryDirectory() as tmp:
            sim = Sim(trial_scene(draw, Path(tmp)), {**draw.layout, LOOKALIKE: draw.pose})
        try:
            seen = appearance(sim, [TARGET, LOOKALIKE])
        finally:
            sim.close()
        white_seen, twin_seen = seen[TARGET], seen[LOOKALIKE]
        if white_seen is not None and twin_seen is not None:
            diffs.append(np.subtract(twin_seen, white_seen))
    a = np.abs(np.array(diffs))
    return {
        "twins": n,
        "seed": CALIBRATION_SEED,
        "seen": len(diffs),
        "threshold": np.percentile(a, 95, axis=0).tolist(),
        "max": a.max(axis=0).tolist(),
    }


def indistinguishable(
    white: list[float] | None, other: list[float] | None, threshold: Sequence[float]
) -> bool | None:
    """Whether every channel of ``other`` lies within ``threshold`` of ``white``'s (a
    white twin's 95th percentile, :func:`calibrate`); None when either was not seen."""
    if white is None or other is None:
        return None
    return bool(np.all(np.abs(np.subtract(white, other)) <= np.asarray(threshold)))


# --- trials -------------------------------------------------------------------------------


@functools.cache
def _tree(path: str) -> Any:
    from smccli.learn.tree import load_tree

    return load_tree(Path(path))


def run_trial(tree_path: str, seed: int, index: int, threshold: Sequence[float]) -> dict[str, Any]:
    """Trial ``index`` of the campaign with ``seed``: its scene file, the first frame's
    :func:`appearance`, the episode and its own verdict, as a row of the table."""
    from threadpoolctl import threadpool_limits

    from smccli.execute.episode import episode, resolve
    from smccli.world.sim import Sim

    draw = draw_trial(learning_scene(), seed, index)
    layout = {**draw.layout, LOOKALIKE: draw.pose}
    with tempfile.TemporaryDirectory() as tmp:
        tree, scene = resolve(_tree(tree_path), trial_scene(draw, Path(tmp)))
        sim = Sim(scene, layout)
        try:
            seen = appearance(sim, [TARGET, LOOKALIKE])
            with threadpool_limits(limits=1):
                r = episode(tree, scene, layout, seed=seed, sim=sim)
        finally:
            sim.close()
    goals = [
        [round(math.dist(d.mapped_goal[:2], layout[k][:2]), 4) for k in (TARGET, LOOKALIKE)]
        for d in r.decisions
        if d.mapped_goal is not None
    ]
    return {
        "trial": index,
        "kind": draw.kind,
        "grey": draw.rgb[0] if draw.kind == "grey" else None,
        "rgb": list(draw.rgb),
        "size_factor": list(draw.factor),
        "placement": draw.placement,
        "gap_m": draw.gap,
        "pose": list(draw.pose),
        "white_box": list(layout[TARGET]),
        "success": r.success,
        "outcome": r.outcome,
        "reason": r.reason,
        "indistinguishable": indistinguishable(seen[TARGET], seen[LOOKALIKE], threshold),
        "appearance": seen,
        "goal_to_white_and_lookalike_m": goals,
        "wall_s": r.wall_time,
    }


def run_trials(
    tree: Path, seed: int, indices: Sequence[int], workers: int, threshold: Sequence[float]
) -> list[dict[str, Any]]:
    """:func:`run_trial` for each of ``indices``, over ``workers`` processes started clean
    (:mod:`smccli.workers`); rows in index order, the same for any number of workers."""
    from itertools import repeat

    from smccli.workers import clean_context

    if workers <= 1:
        return [run_trial(str(tree), seed, i, list(threshold)) for i in indices]
    args = (repeat(str(tree)), repeat(seed), indices, repeat(list(threshold)))
    with ProcessPoolExecutor(workers, mp_context=clean_context([__name__])) as pool:
        return list(pool.map(run_trial, *args))


# --- tables -------------------------------------------------------------------------------


def grey_band(row: dict[str, Any]) -> str:
    """The row's colour band: ``near-colours`` or the grey band holding its grey level."""
    if row["grey"] is None:
        return "near-colours"
    lo, hi = next(b for b in GREY_BANDS if row["grey"] < b[1] or b == GREY_BANDS[-1])
    return f"{lo:.2f}-{hi:.2f}"


def gap_band(row: dict[str, Any]) -> str:
    """The row's band of edge-to-edge gap to the white box."""
    return next(name for name, lo, hi in GAP_BANDS if lo <= row["gap_m"] < hi)


def band_table(
    rows: Sequence[dict[str, Any]], band: Any, names: Sequence[str]
) -> list[dict[str, Any]]:
    """Success per band (``band(row)`` names it) over the trials a person can tell apart
    (the goal's), with Wilson 95 % intervals; the indistinguishable ones counted apart."""
    out = []
    for name in names:
        mine = [r for r in rows if band(r) == name]
        goal = [r for r in mine if r["indistinguishable"] is not True]
        twins = [r for r in mine if r["indistinguishable"] is True]
        ok = sum(r["success"] for r in goal)
        failures: dict[str, int] = {}
        for r in goal:
            if not r["success"]:
                failures[r["outcome"]] = failures.get(r["outcome"], 0) + 1
        out.append(
            {
                "band": name,
                "trials": len(goal),
                "successes": ok,
                "success_rate": ok / len(goal) if goal else None,
                "ci95": list(wilson(ok, len(goal))),
                "failures": failures,
                "indistinguishable": len(twins),
                "indistinguishable_successes": sum(r["success"] for r in twins),
            }
        )
    return out


def summarize(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Overall, by grey band and by gap band (:func:`band_table`)."""
    greys = [f"{lo:.2f}-{hi:.2f}" for lo, hi in GREY_BANDS] + ["near-colours"]
    return {
        "overall": band_table(rows, lambda r: "all", ["all"])[0],
        "by_grey": band_table(rows, grey_band, greys),
        "by_gap": band_table(rows, gap_band, [name for name, _, _ in GAP_BANDS]),
    }


def table_lines(summary: dict[str, Any]) -> list[str]:
    """The summary as a short text table."""
    lines = [f"{'band':<16}{'success':>10}{'95 % CI':>15}  indist.  failures"]
    for key in ("overall", "by_grey", "by_gap"):
        for b in summary[key] if key != "overall" else [summary[key]]:
            lo, hi = b["ci95"]
            lines.append(
                f"{b['band']:<16}{b['successes']:>4}/{b['trials']:<5}"
                f"{100 * lo:>7.1f}-{100 * hi:5.1f} %"
                f"  {b['indistinguishable_successes']}/{b['indistinguishable']:<6} {b['failures']}"
            )
    return lines


FAMILY = {
    "grey": GREY,
    "near_colours": NEAR_COLOURS,
    "near_colour_share": NEAR_COLOUR_SHARE,
    "size_factor_per_axis": SIZE_FACTOR,
    "touching_share": TOUCH_SHARE,
    "near_share": NEAR_SHARE,
    "near_gap_m": NEAR_GAP,
    "area_m": AREA,
}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=300)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=seed_option("lookalike"), default=0, help="or held-out")
    ap.add_argument("--calibration-layouts", type=int, default=CALIBRATION_LAYOUTS)
    ap.add_argument("--out", type=Path, help="docs/bench_lookalike.json, or docs/held_out/...")
    args = ap.parse_args(argv)
    args.out = args.out or results_dir(args.seed) / "bench_lookalike.json"
    from smccli.bench.learning import clumsy_script
    from smccli.learn.compile import compile_logs

    meta = machine()
    cal = calibrate(args.calibration_layouts)
    print(f"a white twin differs by at most {cal['threshold']} (95 %)", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        logs = record_demos(work, 1, first=args.seed)
        tree = work / "tree.json"
        compile_logs(logs, tree, rebuild=True)
        rows = run_trials(tree, args.seed, range(args.trials), args.workers, cal["threshold"])
    summary = summarize(rows)
    print("\n".join(table_lines(summary)), flush=True)
    write_rows(
        args.out,
        "smccli.bench.lookalike",
        argv,
        meta,
        rows,
        scene=str(SCENE.relative_to(REPO)),
        script=clumsy_script(args.seed),
        demonstration=logs[0].name,
        family=FAMILY,
        calibration=cal,
        **summary,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
