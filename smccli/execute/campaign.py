"""Replay campaigns: N randomised layouts of a scene, in parallel, with statistics.

Trial ``i`` of a campaign with seed ``S`` runs on ``sample_layout(scene,
np.random.default_rng([S, i]))``, so a campaign gives the same layouts and the same results
whatever the number of workers (each trial starts from the state a fresh simulation has:
a worker keeps one simulator and resets it; perception and control are deterministic).
A trial runs on one BLAS thread (numpy's and scipy's OpenBLAS): the workers are the
parallelism, and idle OpenBLAS threads spinning beside them take CPU from the trials.
Workers are processes started clean (:mod:`smccli.workers`: EGL contexts do not survive
``fork``), or the workers of an existing Dask cluster (``cluster``: its scheduler's
address), each trial one task. Campaigns write no replay log and render only at decision
points.

Statistics: success rate with a Wilson 95 % interval; success by distance band of the
manipulated object's start from its nominal (demonstrated) position (paper Fig. 11);
failures by cause (see :data:`smccli.execute.evaluation.OUTCOMES`); decision latency percentiles
(perceive + match, paper Fig. 12a); task duration against the demonstration's (Fig. 12b).
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import json  # noqa: E402
import math  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Iterator, Mapping, Sequence  # noqa: E402
from dataclasses import asdict, dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

from smccli.errors import SmcError  # noqa: E402
from smccli.execute.episode import episode, layout_for, resolve, scene_note  # noqa: E402
from smccli.execute.evaluation import OUTCOMES  # noqa: E402
from smccli.execute.executor import LOOK_PERIOD, check_look_period, check_speed  # noqa: E402
from smccli.learn.tree import Tree, digest  # noqa: E402
from smccli.outputs import check_output, write_atomic  # noqa: E402
from smccli.workers import clean_context  # noqa: E402
from smccli.world.geometry import wrap  # noqa: E402
from smccli.world.scene import ROBOT_KEY, Layout, Scene  # noqa: E402
from smccli.world.sim import OdometryDrift, Sim  # noqa: E402

BANDS = (0.0, 0.05, 0.10, 0.15, 0.20, 0.25, 0.30, math.inf)
"""Edges of the distance bands [m] (paper Fig. 11 uses rings around the demonstrated pose)."""
BASE_BANDS = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, math.inf)
"""Edges of the bands of a mobile base's start distance from the scene's nominal start [m]."""
FAILURES = tuple(o for o in OUTCOMES if o != "success")


def wilson(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval (lo, hi) of a binomial proportion, without continuity
    correction (Newcombe 1998); (0, 1) when n = 0. The arithmetic of scipy's
    ``binomtest(k, n).proportion_ci(method="wilson")`` to the bit, written out because
    importing scipy.stats costs a campaign 0.9 s of CPU, more than a trial."""
    if n <= 0:
        return 0.0, 1.0  # no trial: the rate may be anything (scipy refuses n = 0)
    from scipy.special import ndtri  # imported with scipy.spatial already

    p = successes / n
    z = ndtri(0.5 + 0.5 * confidence)
    denom = 2 * (n + z**2)
    center = (2 * n * p + z**2) / denom
    delta = z / denom * math.sqrt(4 * n * p * (1 - p) + z**2)
    lo = 0.0 if successes == 0 else center - delta
    hi = 1.0 if successes == n else center + delta
    return float(lo), float(hi)


@dataclass(frozen=True, slots=True)
class TrialResult:
    """One trial, in plain values (crosses process boundaries, goes into the report)."""

    index: int
    """Trial index i (layout from ``default_rng([seed, i])``)."""
    outcome: str
    """Episode outcome (:data:`smccli.execute.evaluation.OUTCOMES`)."""
    success: bool
    """Success by the scene's criterion."""
    object: str | None
    """The manipulated object."""
    distance: float
    """Its start's horizontal distance from where it was demonstrated (the nearest of the
    tree's demonstrations that recorded their layout; else the scene's nominal pose) [m]."""
    yaw_distance: float
    """Its start yaw's distance from the nominal yaw, modulo a full turn [rad]."""
    path: list[str]
    """Edges taken."""
    latency_ms: list[float]
    """Per decision: perceive + match [ms]."""
    perceive_ms: list[float]
    """Per decision: render + clusters [ms]."""
    match_ms: list[float]
    """Per decision: matching the candidates [ms]."""
    icp_ms: list[float]
    """Per decision: aligning scans, part of matching (mobile base) [ms]."""
    duration: float
    """Task duration [s of sim time]."""
    demo_duration: float
    """Demonstration duration of the path taken [s]."""
    wall_time: float
    """Wall time of the trial [s]."""
    reason: str
    """The criterion's text or what stopped control."""
    layout: dict[str, list[float]]
    """Object poses at the start."""
    decisions: list[dict[str, Any]]
    """Per decision: the edge chosen, every candidate's D_P and the mapped goal, as
    exact floats (a rerun must give the same bits: :meth:`repeatable`)."""
    final_poses: dict[str, list[float]]
    """Object [x, y, z, yaw] at the end (evaluation)."""
    criteria: list[list[Any]] = field(default_factory=list)
    """Every success condition tried at the leaf: [task, what it found, whether it held]."""
    distances: dict[str, float] = field(default_factory=dict)
    """Every object a layout moves: its start's horizontal distance from where it was
    demonstrated (as ``distance``) [m]: the bands of each object."""

    def repeatable(self) -> dict[str, Any]:
        """Every field but the wall-clock timings: what a rerun of the campaign with the
        same seed gives bit for bit, on any number of workers."""
        out = asdict(self)
        for name in WALL_CLOCK_FIELDS:
            del out[name]
        return out


WALL_CLOCK_FIELDS = ("latency_ms", "perceive_ms", "match_ms", "icp_ms", "wall_time")
"""The fields of a :class:`TrialResult` measured by the wall clock (they vary run to run)."""


class SimCache:
    """One simulator per thread, reset for each trial (its model, data and renderer are
    built once): :meth:`get` gives the calling thread's for a scene and drift, building it
    the first time or when they change. Threads matter on a Dask worker, which runs tasks
    on several; a GL context belongs to the thread that made it."""

    def __init__(self) -> None:
        self._local = threading.local()
        self._all: list[Sim] = []
        self._lock = threading.Lock()

    def get(self, scene: Scene, drift: OdometryDrift | None) -> Sim:
        sim: Sim | None = getattr(self._local, "sim", None)
        if sim is not None and sim.scene is scene and sim.drift == drift:
            return sim
        if sim is not None:
            sim.close()
        sim = self._local.sim = Sim(scene, drift=drift)
        with self._lock:
            self._all.append(sim)
        return sim

    def close(self) -> None:
        """Free every simulator's renderer (call from the thread that used them)."""
        with self._lock:
            for sim in self._all:
                sim.close()
            self._all.clear()
        self._local = threading.local()


_SIMS = SimCache()
"""This process's simulators (pool and Dask workers keep theirs between trials)."""


def demo_layouts(tree: Tree) -> list[dict[str, list[float]]]:
    """Where the objects were at the start of each of the tree's demonstrations (the
    recorder's ``layout`` metadata, kept in the tree's history; for reports only: the
    policy never reads it)."""
    return [
        log["layout"]
        for entry in tree.history
        for log in entry.get("logs", ())
        if isinstance(log.get("layout"), dict)
    ]


def demo_distances(
    scene: Scene, layout: Layout, demos: Sequence[Mapping[str, Sequence[float]]]
) -> dict[str, float]:
    """Each object the layout moves (a range, or furniture under it) -> its horizontal
    distance [m] from the nearest demonstration's start of it, or from its nominal pose
    when no demonstration recorded one."""
    out = {}
    for o in scene.objects:
        moves = o.range_x[0] != o.range_x[1] or o.range_y[0] != o.range_y[1] or o.on
        if o.name not in layout or not moves:
            continue
        starts = [d[o.name][:2] for d in demos if o.name in d] or [o.pose[:2]]
        out[o.name] = min(math.dist(layout[o.name][:2], xy) for xy in starts)
    return out


def run_trial(
    tree: Tree,
    scene: Scene,
    seed: int,
    index: int,
    drift: OdometryDrift | None = None,
    speed: float = 1.0,
    sims: SimCache | None = None,
    look_period: float = LOOK_PERIOD,
) -> TrialResult:
    """Trial ``index`` of the campaign with ``seed``, its DMPs ``speed`` times faster; the
    distance bands are over the manipulated object's start, or a mobile base's. The
    simulator comes from ``sims`` (default: this process's)."""
    layout = layout_for(scene, seed, index)
    sim = (sims or _SIMS).get(scene, drift)
    with threadpool_limits(limits=1):
        r = episode(
            tree,
            scene,
            layout,
            seed=seed,
            drift=drift,
            speed=speed,
            sim=sim,
            look_period=look_period,
        )
    obj = r.manipulated
    dist = yaw = 0.0
    distances = demo_distances(scene, layout, demo_layouts(tree))
    if scene.start is not None and ROBOT_KEY in layout:
        obj = ROBOT_KEY
        x, y, _, a = layout[ROBOT_KEY]
        dist = math.dist((x, y), scene.start.pose[:2])
        yaw = abs(wrap(a - scene.start.pose[2]))
    elif obj is not None:
        spec = scene.object(obj)
        dist = distances.get(obj, math.dist(layout[obj][:2], spec.pose[:2]))
        yaw = abs(wrap(layout[obj][3] - spec.pose[3]))
    return TrialResult(
        index=index,
        outcome=r.outcome,
        success=r.success,
        object=obj,
        distance=dist,
        yaw_distance=yaw,
        path=list(r.path),
        latency_ms=r.latencies_ms,
        perceive_ms=[1e3 * d.perceive_s for d in r.decisions],
        match_ms=[1e3 * d.match_s for d in r.decisions],
        icp_ms=[1e3 * d.icp_s for d in r.decisions],
        duration=r.duration,
        demo_duration=r.demo_duration,
        wall_time=r.wall_time,
        reason=r.reason,
        layout={k: list(v) for k, v in layout.items()},
        distances=distances,
        decisions=[
            {
                "chosen": d.chosen,
                "d_p": {c.edge: _exact(c.d_p) for c in d.candidates},
                "goal": None if d.mapped_goal is None else [float(v) for v in d.mapped_goal],
            }
            for d in r.decisions
        ],
        final_poses=r.final_poses,
        criteria=[list(c) for c in r.criteria],
    )


def _exact(x: float) -> float | None:
    """A float as JSON keeps it (None for inf or NaN, which JSON has not)."""
    return float(x) if math.isfinite(x) else None


# --- workers ----------------------------------------------------------------------------

_WORKER: dict[str, Any] = {}


def _init_worker(
    tree: Tree,
    scene: Scene,
    seed: int,
    drift: OdometryDrift | None,
    speed: float = 1.0,
    look_period: float = LOOK_PERIOD,
) -> None:
    _WORKER.update(
        tree=tree, scene=scene, seed=seed, drift=drift, speed=speed, look_period=look_period
    )


def _work(index: int) -> TrialResult:
    w = _WORKER
    return run_trial(
        w["tree"],
        w["scene"],
        w["seed"],
        index,
        w["drift"],
        w["speed"],
        look_period=w["look_period"],
    )


CLUSTER_TIMEOUT = 10.0
"""How long a Dask scheduler has to answer, and to have a worker [s]."""


def cluster_client(address: str):
    """A ``distributed.Client`` of the Dask scheduler at ``address`` with at least one
    worker; an :class:`SmcError` naming the address when there is none."""
    from distributed import Client

    try:
        client = Client(address, timeout=f"{CLUSTER_TIMEOUT}s", set_as_default=False)
    except (OSError, TimeoutError, ValueError, TypeError) as e:
        why = (str(e).splitlines() or [type(e).__name__])[0]
        raise SmcError(
            f"--cluster {address}: no Dask scheduler answered there within "
            f"{CLUSTER_TIMEOUT:.0f} s ({why})"
        ) from None
    try:
        client.wait_for_workers(1, timeout=CLUSTER_TIMEOUT)
    except TimeoutError:
        client.close()
        raise SmcError(
            f"--cluster {address}: the scheduler has no worker (start some with "
            f"`dask worker {address}`)"
        ) from None
    return client


def _cluster_trials(
    tree: Tree,
    scene: Scene,
    seed: int,
    drift: OdometryDrift | None,
    todo: list[int],
    address: str,
    speed: float = 1.0,
    look_period: float = LOOK_PERIOD,
) -> Iterator[TrialResult]:
    """Each trial of ``todo`` as one task on the Dask cluster at ``address``, yielded as
    they finish. The tree and the scene go to every worker once, not with each task."""
    from distributed import as_completed

    with cluster_client(address) as client:
        tree_f, scene_f = client.scatter([tree, scene], broadcast=True, hash=False)
        futures = [
            client.submit(
                run_trial,
                tree_f,
                scene_f,
                seed,
                i,
                drift,
                speed,
                look_period=look_period,
                pure=False,
            )
            for i in todo
        ]
        try:
            for fut in as_completed(futures, loop=client.loop):
                yield fut.result()
        finally:
            client.cancel(futures)


def run_trials(
    tree: Tree,
    scene: Scene,
    *,
    trials: int,
    seed: int = 0,
    workers: int = 1,
    on_trial: Callable[[int, int], None] | None = None,
    indices: Sequence[int] | None = None,
    drift: OdometryDrift | None = None,
    cluster: str | None = None,
    speed: float = 1.0,
    look_period: float = LOOK_PERIOD,
) -> list[TrialResult]:
    """Run the trials (``range(trials)`` or ``indices``) over ``workers`` processes, or on
    the Dask cluster whose scheduler is at ``cluster``; results in index order, the same
    either way. ``on_trial(done, successes)`` after each; ``speed``: every DMP that many
    times faster; ``look_period``: how often an arm looks again at what it acts on [s]."""
    todo = list(range(trials)) if indices is None else list(indices)
    results: list[TrialResult] = []
    ok = 0

    def done(res: TrialResult) -> None:
        nonlocal ok
        results.append(res)
        ok += res.success
        if on_trial:
            on_trial(len(results), ok)

    if cluster is not None:
        for res in _cluster_trials(tree, scene, seed, drift, todo, cluster, speed, look_period):
            done(res)
    elif workers <= 1 or len(todo) <= 1:
        sims = SimCache()  # this process's: freed when the campaign ends
        try:
            for i in todo:
                done(run_trial(tree, scene, seed, i, drift, speed, sims, look_period))
        finally:
            sims.close()
    else:
        ctx = clean_context([__name__])
        with ctx.Pool(
            min(workers, len(todo)),
            initializer=_init_worker,
            initargs=(tree, scene, seed, drift, speed, look_period),
        ) as pool:
            for res in pool.imap_unordered(_work, todo, chunksize=1):
                done(res)
    return sorted(results, key=lambda r: r.index)


# --- statistics -------------------------------------------------------------------------


def _pct(values: Sequence[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if len(values) else None


def _bands(trials: Sequence[tuple[float, bool]], bands: Sequence[float]) -> list[dict[str, Any]]:
    """Success by distance band: (distance [m], success) per trial -> one row per band."""
    rows = []
    for lo, hi in zip(bands[:-1], bands[1:], strict=True):
        sel = [ok for d, ok in trials if lo <= d < hi]
        if not sel and math.isinf(hi):
            continue
        k = sum(sel)
        rows.append(
            {
                "band": [lo, None if math.isinf(hi) else hi],
                "label": f"{lo:.2f}-{hi:.2f} m" if not math.isinf(hi) else f">{lo:.2f} m",
                "trials": len(sel),
                "successes": k,
                "success_rate": k / len(sel) if sel else None,
                "ci95": list(wilson(k, len(sel))),
            }
        )
    return rows


def summarize(
    results: Sequence[TrialResult],
    *,
    scene: Scene,
    tree: Tree,
    seed: int,
    workers: int,
    wall_s: float,
    bands: Sequence[float] = BANDS,
) -> dict[str, Any]:
    """The campaign summary (the ``--report`` JSON)."""
    n = len(results)
    succ = sum(r.success for r in results)
    by_band = _bands([(r.distance, r.success) for r in results], bands)
    failures = {c: sum(r.outcome == c for r in results) for c in FAILURES}
    lat = [v for r in results for v in r.latency_ms]
    per = [v for r in results for v in r.perceive_ms]
    mat = [v for r in results for v in r.match_ms]
    icp = [v for r in results for v in r.icp_ms]
    done = [r for r in results if r.success]
    dur = [r.duration for r in done]
    ratio = [r.duration / r.demo_duration for r in done if r.demo_duration > 0]
    return {
        "scene": scene.name,
        "robot": scene.robot.name,
        "tree_digest": digest(tree),
        "seed": seed,
        "workers": workers,
        "trials": n,
        "successes": succ,
        "success_rate": succ / n if n else 0.0,
        "ci95": list(wilson(succ, n)),
        "by_band": by_band,
        "by_object": {
            name: _bands(
                [(r.distances[name], r.success) for r in results if name in r.distances], bands
            )
            for name in sorted({k for r in results for k in r.distances})
        },
        "failures": failures,
        "latency_ms": {
            "p50": _pct(lat, 50),
            "p95": _pct(lat, 95),
            "max": max(lat, default=None),
            "perceive_p50": _pct(per, 50),
            "match_p50": _pct(mat, 50),
            "match_p95": _pct(mat, 95),
            "perceive_p95": _pct(per, 95),
            "icp_p50": _pct(icp, 50),
            "icp_p95": _pct(icp, 95),
            "decisions": len(lat),
        },
        "duration_s": {
            "p50": _pct(dur, 50),
            "p95": _pct(dur, 95),
            "demo": _pct([r.demo_duration for r in done], 50),
            "ratio_p50": _pct(ratio, 50),
        },
        "wall_s": wall_s,
        "trials_per_second": n / wall_s if wall_s > 0 else None,
        "trial_results": [asdict(r) for r in results],
    }


def run_campaign(
    tree: Path | Tree,
    *,
    scene: str | Path | Scene | None = None,
    trials: int,
    seed: int = 0,
    workers: int = 1,
    report: Path | None = None,
    on_trial: Callable[[int, int], None] | None = None,
    force: bool = False,
    drift: OdometryDrift | None = None,
    cluster: str | None = None,
    speed: float = 1.0,
    look_period: float = LOOK_PERIOD,
) -> dict[str, Any]:
    """``smc replay TREE --trials N --seed S --workers W [--report FILE]``: the summary.
    ``cluster``: the address of a Dask scheduler whose workers run the trials instead
    (``--cluster``; ``workers`` is then theirs); ``speed``: every DMP that many times
    faster (``--speed``; SmcError beyond the tree's limit, before the first trial);
    ``look_period``: how often an arm looks again at what it acts on (``--look-period``
    [s], 0: never).

    The report is checked before the first trial (folder writable; an existing file needs
    ``force``) and written atomically.
    """
    if trials <= 0:
        raise SmcError(f"--trials must be positive, found {trials}")
    if report is not None:
        check_output(report, force=force)
    t, sc = resolve(tree, scene)
    check_speed(t, speed)
    check_look_period(look_period)
    wall0 = time.perf_counter()
    if cluster is not None:
        with cluster_client(cluster) as client:  # fail before the first trial, not after
            workers = len(client.scheduler_info()["workers"])
    results = run_trials(
        t,
        sc,
        trials=trials,
        seed=seed,
        workers=workers,
        on_trial=on_trial,
        drift=drift,
        cluster=cluster,
        speed=speed,
        look_period=look_period,
    )
    summary = summarize(
        results,
        scene=sc,
        tree=t,
        seed=seed,
        workers=workers,
        wall_s=time.perf_counter() - wall0,
        bands=BASE_BANDS if sc.start is not None else BANDS,
    )
    summary["tree"] = None if isinstance(tree, Tree) else str(tree)
    summary["note"] = scene_note(t, sc)
    summary["odometry_drift"] = None if drift is None else asdict(drift)
    summary["cluster"] = cluster
    summary["speed"] = speed
    summary["look_period"] = look_period
    if report is not None:
        write_atomic(report, json.dumps(summary, indent=1, allow_nan=False) + "\n")
    return summary
