"""``smc compile``: demonstration logs -> SMC chains -> the tree (paper 3.1-3.8, Algorithm 1).

Per log, in order: read -> temporal saliency (fragments) -> perception saliency ->
action saliency -> SMCs; then Algorithm 1 inserts the chain into the tree. Compile only
perceives through the logged sensors (camera, scale, the robot's own joints for the
self-filter); ``/sim/ground_truth`` is never read.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import json
import multiprocessing
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from smccli import __version__
from smccli.errors import LogError, SmcError, TreeError
from smccli.learn.mobile import base_smcs, mobile_manipulator_smcs
from smccli.learn.params import SmcParams, params_to_dict, with_overrides
from smccli.learn.segmentation import (
    Fragment,
    SegmentMode,
    fragment_commands,
    segment,
    trace_from_commands,
)
from smccli.learn.smc import (
    Action,
    SalientPerceptions,
    Smc,
    Source,
    action_from_path,
)
from smccli.learn.tree import FORMAT, ROOT, Tree, digest, insert_chain, load_tree, save_tree
from smccli.learn.trim import active_times, idle_centres
from smccli.logs import Log, read_log
from smccli.logs import topics as tp
from smccli.logs.robot import geometry_at, robot_model_of
from smccli.logs.ros2_bag import ROLE_OF, ROLES, TopicMap, read_ros2_bag
from smccli.outputs import ExclusiveLock, check_output
from smccli.perception import Cluster, clusters_from_frame, salient_cluster, scale_reading
from smccli.perception.params import scene_perception
from smccli.perception.workspace import crop_warnings
from smccli.world.robot import Robot
from smccli.world.scene import Scene, robot_identity, scene_of_log, sensor_identity


@dataclass(frozen=True, slots=True)
class Chain:
    """The SMCs extracted from one log, in time order."""

    log: Path
    """The log file."""
    sha256: str
    """Its sha256 (hex)."""
    fragments: tuple[Fragment, ...]
    """Temporal saliency: the fragments."""
    smcs: tuple[Smc, ...]
    """One SMC per fragment."""
    warnings: tuple[str, ...]
    """One-line warnings (truncated log, no boundary, no salient object...)."""
    at: str | None = None
    """Where the chain was taught during replay (``smc replay --teach``) and inserted; None:
    a demonstration of the whole task, inserted at the root."""


@dataclass(frozen=True, slots=True)
class CompileResult:
    """What a compile did."""

    tree: Tree
    """The tree after the compile (written to disk unless unchanged)."""
    added: tuple[Chain, ...]
    """Logs inserted by this compile."""
    skipped: tuple[Path, ...]
    """Logs already in the tree."""
    changed: bool
    """Whether the file was rewritten (version grew)."""


def _finger_speed(log: Log, fingers: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Largest speed of the gripper joints ``fingers`` over time, for settling the gripper
    edges."""
    t = np.array([js.t for js in log.joint_states], dtype=float)
    if not log.joint_states:
        return t, np.zeros(0)
    names = log.joint_states[0].names
    idx = [i for i, n in enumerate(names) if n in fingers]
    if not idx:
        return t, np.zeros(len(t))
    vel = np.abs(np.array([js.velocity for js in log.joint_states])[:, idx]).max(axis=1)
    return t, vel


def fragments(
    log: Log,
    params: SmcParams,
    mode: SegmentMode = SegmentMode.markers,
    robot: Robot | None = None,
) -> list[Fragment]:
    """Temporal saliency (3.1) of a log: its fragments, as compile cuts them. ``robot``:
    the log's (default: read from its attachments)."""
    robot = robot or scene_of_log(log.attachments, log.path).robot
    t_end = float(log.poi_t[-1]) if len(log.poi_t) else 0.0
    t_f, v_f = _finger_speed(log, robot.gripper.joints if robot.gripper else ())
    marks = tuple(m.t for m in log.marks if m.source == "operator")
    trace = trace_from_commands(log.commands, t_f, v_f, log.weight_t, log.weight, marks, t_end)
    return segment(
        trace,
        mode,
        snap_window=params.snap_window,
        min_fragment=params.min_fragment,
        auto_gap=params.auto_gap,
        idle=params.idle,
    )


def extract_chain(
    log: Log, params: SmcParams, mode: SegmentMode, scene: Scene | None = None
) -> Chain:
    """Temporal, perception and action saliency of one log -> its SMC chain (eq. 40-42).
    ``scene``: the log's (default: rebuilt from its attachments)."""
    warnings: list[str] = []
    name = log.path.name
    scene = scene or scene_of_log(log.attachments, log.path)
    if mode is SegmentMode.markers and not any(m.source == "operator" for m in log.marks):
        warnings.append(
            f"{name}: no saliency marks; the whole log is one fragment (try --segment auto)"
        )
    frags = fragments(log, params, mode, scene.robot)
    if log.truncated or log.interrupted:
        # Only what a boundary closed is a whole fragment: the rest was cut mid-action.
        how = "truncated" if log.truncated else f"interrupted ({log.end.get('reason', '?')})"
        t_end = float(log.poi_t[-1]) if len(log.poi_t) else 0.0
        if frags[-1].cause == "end":
            raise LogError(
                f"{log.path}: {how} at t={t_end:.1f} s before its first fragment "
                "boundary; no complete fragment to compile"
            )
        warnings.append(
            f"{name}: {how} at t={t_end:.1f} s; compiled {len(frags)} complete "
            f"fragment(s) up to t={frags[-1].t1:.1f} s, dropped the last "
            f"{t_end - frags[-1].t1:.1f} s"
        )
    if scene.robot.base is not None:
        smc_of = mobile_manipulator_smcs if scene.robot.arm_joints else base_smcs
        return Chain(
            log=log.path,
            sha256=log.sha256,
            fragments=tuple(frags),
            smcs=tuple(smc_of(log, frags, scene, params, warnings)),
            warnings=tuple(warnings),
        )
    robot = robot_model_of(log)
    has_scale = len(log.weight) > 0
    cut_faces: set[str] = set()
    smcs: list[Smc] = []
    held = 0.0  # symmetry of the object in the hand: nothing yet
    for k, frag in enumerate(frags):
        frame = log.frame_at(frag.t0)
        if frame is None:
            raise LogError(f"{name}: no camera frame near t={frag.t0:.2f} s")
        clusters = clusters_from_frame(frame, geometry_at(robot, log, frame.t), params.perception)
        warnings += crop_warnings(name, frame.t, clusters, params.perception, cut_faces)
        poi_end = log.poi[int(np.argmin(np.abs(log.poi_t - frag.t1)))]
        idx = salient_cluster(clusters, poi_end[:3], params.epsilon)
        cluster = None if idx is None else clusters[idx]
        weight = None
        if has_scale:
            weight = scale_reading(log.weight_t, log.weight, frag.t0, params.weight_window)
        action = _action(log, frag, cluster, held, params)
        if action.event == "close":  # what the hand holds from here on
            held = cluster.yaw_period if cluster is not None else 0.0
        elif action.event == "open":
            held = 0.0
        if cluster is None and action.event != "none":
            warnings.append(
                f"{name}: fragment {k + 1} ({frag.t0:.1f}-{frag.t1:.1f} s) ends "
                f"with no object within {params.epsilon} m of the POI; its goal "
                "is stored in the world frame"
            )
        smcs.append(
            Smc(perception=SalientPerceptions(cluster=cluster, weight=weight), action=action)
        )
    return Chain(
        log=log.path,
        sha256=log.sha256,
        fragments=tuple(frags),
        smcs=tuple(smcs),
        warnings=tuple(warnings),
    )


def demonstration_warnings(path: Path, scene: Scene) -> tuple[str, ...]:
    """What compile will warn about a demonstration just recorded in ``scene`` (an object
    the crop box cuts, a fragment ending far from any object...), or the one line it would
    refuse it with: said by ``smc record`` while the operator is still there."""
    try:
        log = read_log(path, topics=tp.READ_TOPICS, lazy_frames=True)
        return extract_chain(log, scene_params(scene), SegmentMode.markers, scene).warnings
    except SmcError as e:
        return (f"compile would refuse it: {e}",)


def _action(
    log: Log, frag: Fragment, cluster: Cluster | None, held_symmetry: float, params: SmcParams
) -> Action:
    """Action saliency (3.4): the commanded POI path over the fragment as a DMP, its goal
    and approach in the salient object's frame; ``held_symmetry`` is that of the object in
    the hand (see :class:`smccli.learn.smc.Action`)."""
    cmds = fragment_commands(log, frag)
    t = np.array([c.t for c in cmds]) - cmds[0].t
    path = np.array([c.target for c in cmds], dtype=float)
    grip = np.array([c.gripper for c in cmds])
    if params.idle.squeeze:  # the DMP and the gripper phase on the clock of the motion
        idle = idle_centres(t, path, grip, None, params.idle)
        t = active_times(t, idle, params.idle, keep=params.idle.keep)
    return action_from_path(t, path, grip, cluster, params, held_symmetry=held_symmetry)


def required_topics(log: Log, scene: Scene | None = None) -> set[str]:
    """The topics compile needs in ``log`` (its scene's robot decides: an arm, a base, a
    mobile manipulator; default: the scene the log carries, else an arm's)."""
    if scene is None:  # doctor: the log's own scene, if it can be rebuilt
        try:
            scene = scene_of_log(log.attachments, log.path)
        except LogError:
            scene = None
    if scene is not None and scene.robot.base is not None:
        if scene.robot.arm_joints:  # a mobile manipulator: both, and its base pose
            return set(tp.BASE_TOPICS | tp.ARM_TOPICS | {tp.BASE})
        return set(tp.BASE_TOPICS)
    needed = set(tp.ARM_TOPICS)
    if log.metadata.get("has_scale") == "true":
        needed.add("/scale/weight")
    return needed


def scene_params(scene: Scene, overrides: Sequence[str] = ()) -> SmcParams:
    """The parameters a new tree of ``scene`` starts with: the defaults, the scene's
    perception settings (scene.yaml ``perception``: a mobile manipulator's crop box in its
    base's frame), then ``overrides`` (``--set``)."""
    params = replace(SmcParams(), perception=scene_perception(scene))
    return with_overrides(params, list(overrides))


def _rebuild_base(out: Path) -> tuple[int, tuple[dict, ...]]:
    """Version and history of the tree a ``--rebuild`` replaces. Its contents are discarded,
    so a tree an older smc wrote (another schema) is fine; a file that is no smc tree at
    all is refused, never replaced."""
    try:
        old = load_tree(out)
        return old.version, old.history
    except TreeError:
        try:
            doc = json.loads(out.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError):
            doc = None
        if not isinstance(doc, dict) or doc.get("format") != FORMAT:
            raise
        version, history = doc.get("version"), doc.get("history")
        if not (isinstance(version, int) and isinstance(history, list)):
            return 0, ()
        return version, tuple(h for h in history if isinstance(h, dict))


@dataclass(frozen=True, slots=True)
class _Job:
    """One log to read and extract, for a worker process: paths and small frozen values."""

    path: Path
    params: SmcParams
    """The tree's parameters."""
    fresh: bool
    """The tree is new and holds no log yet: it takes its first log's scene's perception
    settings (:func:`scene_params`: the scene file's, an arm's crop box from its reach)."""
    overrides: tuple[str, ...]
    """``--set`` assignments."""
    segment_mode: SegmentMode
    known: frozenset[str]
    """Digests of the logs in the tree: such a log is read (its errors count) but not
    extracted, it will be skipped."""
    topic_map: TopicMap | None
    """Read a ROS 2 bag through this map; None: an MCAP log."""
    strict: bool = False
    """Refuse a demonstration its recorder found had failed its task (else a warning)."""


@dataclass(frozen=True, slots=True)
class _Read:
    """What reading and extracting one log gave. The errors are kept, not raised, so that
    the sequential part raises them where a one-log-at-a-time compile would."""

    path: Path
    warnings: tuple[str, ...]
    """Warnings while reading (truncated, dropped frames...), in order."""
    error: SmcError | None = None
    """The log is refused: unreadable, its scene does not load, a topic is missing."""
    sha256: str = ""
    metadata: dict[str, str] = field(default_factory=dict)
    """The log's ``smc`` metadata record."""
    model_error: SmcError | None = None
    """The scene's MJCF does not compile (only looked at for a log not in the tree)."""
    robot: dict[str, str] = field(default_factory=dict)
    """:func:`robot_identity`."""
    sensors: dict[str, Any] = field(default_factory=dict)
    scene_files: dict[str, str] = field(default_factory=dict)
    """The scene's files as the log carries them (``scene.yaml``, ``scene.xml``,
    ``robot.yaml``): the tree keeps its first log's, to run where it was taught."""
    """:func:`sensor_identity`."""
    scene_params: SmcParams | SmcError | None = None
    """With ``_Job.fresh``: :func:`scene_params` (or why not)."""
    params: SmcParams | None = None
    """What the chain was extracted with; None: not extracted."""
    chain: Chain | SmcError | None = None
    """:func:`extract_chain` (or why not)."""


def _read(job: _Job) -> _Read:
    """Read one log and extract its chain: the part of a compile that needs no tree, run in
    a worker process (or in process with one worker)."""
    warnings: list[str] = []
    path = job.path
    try:
        log = (
            read_log(path, topics=tp.READ_TOPICS, on_warning=warnings.append, lazy_frames=True)
            if job.topic_map is None
            else read_ros2_bag(path, job.topic_map, on_warning=warnings.append)
        )
        scene = scene_of_log(log.attachments, path)
        missing = sorted(
            required_topics(log, scene) - {t for t, n in log.topic_counts.items() if n > 0}
        )
        task = log.task
        if task is not None and task["success"] is False:
            what = f"{path}: the demonstration failed its task ({task.get('reason', '?')})"
            if job.strict:
                raise LogError(f"{what}; compile --strict refuses it")
            warnings.append(f"{what}; its SMCs teach what it did (--strict refuses it)")
        if missing:
            scene_name = log.metadata.get("scene", "?")
            if job.topic_map is not None:  # say it in the bag's terms: the map's role
                role = ROLE_OF.get(missing[0], "?")
                raise LogError(
                    f"{path}: the topic map gives no {role} topic (scene {scene_name} needs "
                    f"one: {' or '.join(ROLES[role][1]) if role in ROLES else missing[0]})"
                )
            raise LogError(f"{path}: topic {missing[0]} missing (scene {scene_name} needs it)")
    except SmcError as e:
        return _Read(path, tuple(warnings), error=e)
    files = {n: bytes(v).decode() for n, v in log.attachments.items() if n in SCENE_FILES}
    read = _Read(
        path, tuple(warnings), sha256=log.sha256, metadata=dict(log.metadata), scene_files=files
    )
    if log.sha256 in job.known:
        return read
    try:
        model = scene.model()
        robot, sensors = robot_identity(scene, model), sensor_identity(scene, model)
    except SmcError as e:
        return replace(read, model_error=e)
    read = replace(read, robot=robot, sensors=sensors)
    params = job.params
    if job.fresh:  # the scene's perception settings, an arm's crop box from its reach
        try:
            params = scene_params(scene, job.overrides)
        except SmcError as e:
            return replace(read, scene_params=e)
        read = replace(read, scene_params=params)
    try:
        chain: Chain | SmcError = extract_chain(log, params, job.segment_mode, scene)
    except SmcError as e:
        chain = e
    return replace(read, params=params, chain=chain)


def parse_layout(text: str | None) -> dict[str, list[float]] | None:
    """The recorder's ``layout`` metadata (JSON: object -> [x, y, z, yaw]), or None when
    absent or malformed (a report's distance bands then fall back to the nominal poses)."""
    try:
        doc = json.loads(text) if text else None
    except ValueError:
        return None
    if not isinstance(doc, dict):
        return None
    ok = all(
        isinstance(v, list) and len(v) == 4 and all(isinstance(x, (int, float)) for x in v)
        for v in doc.values()
    )
    return {str(k): [float(x) for x in v] for k, v in doc.items()} if ok else None


SCENE_FILES = ("scene.yaml", "scene.xml", "robot.yaml")
"""The attachments that hold a log's scene (:func:`smccli.world.scene.scene_of_log`)."""
PARALLEL_MIN_LOGS = 6
"""Fewer logs than this compile in process by default: starting workers costs about as
much as reading five logs (measured: 2 logs take 1.6 s in workers, 0.8 s in process)."""


def default_workers(n_logs: int) -> int:
    """Worker processes of a compile of ``n_logs`` logs by default: one per CPU this
    process may use, at most one per log; in process below :data:`PARALLEL_MIN_LOGS`."""
    if n_logs < PARALLEL_MIN_LOGS:
        return 1
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, min(cpus or 1, n_logs))


def _pool(workers: int) -> ProcessPoolExecutor:
    """Worker processes that never fork a process holding MuJoCo or GL state: a fork
    server that has only imported this module (no model, no context) forks them, which
    spares each the ~2 s of imports (and a later compile in the same process the server's);
    spawn where there is no fork server. Not the caller's ``__main__``: a script without
    the ``if __name__ == "__main__":`` guard would run in the server."""
    methods = multiprocessing.get_all_start_methods()
    ctx = multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")
    if ctx.get_start_method() == "forkserver":
        ctx.set_forkserver_preload([__name__])
    return ProcessPoolExecutor(workers, mp_context=ctx)


WORKER_ENV = {"OPENBLAS_THREAD_TIMEOUT": "4"}
"""Environment of the worker processes, where the user has not set it. OpenBLAS's idle
threads spin for 2**28 cycles (~0.1 s) after every call before they sleep; with a worker
per core, each one's spinning threads take the others' cores (20 demos: 12.5 s instead of
6.5 s on 2 cores). With 2**4 they sleep at once. The DMP fit runs on one BLAS thread
wherever it runs (smccli/learn/dmp.py), so the tree does not depend on the thread count."""


@contextlib.contextmanager
def _worker_env() -> Iterator[None]:
    """:data:`WORKER_ENV` for the processes started inside (the fork server, or each spawned
    worker, takes the environment when it starts), then the environment as it was."""
    added = {k: v for k, v in WORKER_ENV.items() if k not in os.environ}
    os.environ.update(added)
    try:
        yield
    finally:
        for k in added:
            os.environ.pop(k, None)


def _result(future: Future[_Read], path: Path) -> _Read:
    try:
        return future.result()
    except BrokenProcessPool:
        raise LogError(
            f"{path}: the worker process compiling it died (out of memory? killed?); "
            "--workers 1 compiles in process"
        ) from None


def _same(a: SmcParams, b: SmcParams) -> bool:
    return params_to_dict(a, full=True) == params_to_dict(b, full=True)


def compile_logs(
    logs: Sequence[Path],
    out: Path,
    *,
    segment_mode: SegmentMode = SegmentMode.markers,
    rebuild: bool = False,
    overrides: Sequence[str] = (),
    on_progress: Callable[[Path, str], None] | None = None,
    on_warning: Callable[[str], None] | None = None,
    topic_map: TopicMap | None = None,
    workers: int | None = None,
    strict: bool = False,
) -> CompileResult:
    """Add the logs to the tree at ``out`` (created if absent) and write it atomically.

    A log already in the tree is skipped. Parameters that differ from the tree's are
    refused unless ``rebuild``. Any bad log aborts the compile before the file is touched.
    With ``topic_map`` the logs are ROS 2 bags read through it
    (:func:`smccli.logs.ros2_bag.read_ros2_bag`).

    ``workers`` processes (default: one per CPU, at most one per log; 1: in this process)
    read the logs and extract their chains in parallel; the tree takes them in the order
    given (Algorithm 1 is sequential), so the tree, the warnings and the first error are
    those of a one-log-at-a-time compile.

    A demonstration whose recorder found it failed its task (the log's ``smc_end``) is
    compiled with a warning, or refused with ``strict``.
    """
    paths = [Path(p) for p in logs]
    n_workers = default_workers(len(paths)) if workers is None else workers
    if n_workers < 1:
        raise SmcError(f"workers: expected 1 or more, got {workers}")
    # The tree is updated in place by design (Algorithm 1 is incremental); what must hold
    # before reading any log is that it can be written at all.
    out = check_output(out, force=True)
    warn = on_warning or (lambda msg: None)
    lock = ExclusiveLock(f"{out}.lock")
    try:
        lock.acquire(timeout=60)
    except TimeoutError:
        raise TreeError(f"{out}: locked by another compile ({out}.lock)") from None
    pool = None
    try:
        fresh = not (out.exists() and not rebuild)
        # A new tree takes its scene's perception settings (scene.yaml), then --set.
        if not fresh:
            tree = load_tree(out)
            wanted = with_overrides(tree.params, list(overrides))
            if params_to_dict(wanted) != params_to_dict(tree.params):
                raise TreeError(
                    f"{out}: --set {' '.join(overrides)} differs from the tree's "
                    "parameters; use --rebuild to start afresh"
                )
        else:
            # A rebuild starts a new tree but keeps the version growing and the history.
            version, history = _rebuild_base(out) if out.exists() else (0, ())
            tree = Tree(
                params=with_overrides(SmcParams(), list(overrides)),
                version=version,
                history=history,
            )
        known = tree.log_digests()
        added: list[Chain] = []
        layouts: dict[str, dict[str, list[float]]] = {}
        skipped: list[Path] = []

        def job(path: Path) -> _Job:
            """The job as the tree stands now: in process, exactly a sequential compile's."""
            return _Job(
                path,
                tree.params,
                fresh and not added,
                tuple(overrides),
                segment_mode,
                frozenset(known) | {c.sha256 for c in added},
                topic_map,
                strict,
            )

        futures: list[Future[_Read]] = []
        if n_workers > 1 and len(paths) > 1:
            # Submitted as the tree stands before the first log; a chain extracted with
            # other parameters than the tree has when its turn comes (a new tree whose
            # logs' scenes differ in perception settings) is extracted again, in process.
            pool = _pool(n_workers)
            with _worker_env():  # the workers start on the first submits
                futures = [pool.submit(_read, job(p)) for p in paths]
        for i, path in enumerate(paths):
            if on_progress:
                on_progress(path, "reading")
            r = _result(futures[i], path) if futures else _read(job(path))
            for w in r.warnings:
                warn(w)
            if r.error is not None:
                raise r.error
            if r.sha256 in known or any(c.sha256 == r.sha256 for c in added):
                skipped.append(path)
                continue
            if r.model_error is not None:
                raise r.model_error
            robot = r.robot
            if tree.robot and tree.robot != robot:
                raise LogError(
                    f"{path}: recorded with robot {robot['name']!r} "
                    f"(kinematics {robot['kinematics'][7:19]}), the tree was taught on "
                    f"{tree.robot.get('name')!r} ({str(tree.robot.get('kinematics'))[7:19]})"
                )
            if tree.scene and r.metadata.get("scene") not in (None, tree.scene.get("name")):
                raise LogError(
                    f"{path}: scene {r.metadata.get('scene')!r} differs from the "
                    f"tree's scene {tree.scene.get('name')!r}"
                )
            if fresh and not added:
                if isinstance(r.scene_params, SmcError):
                    raise r.scene_params
                assert r.scene_params is not None  # computed for every fresh job
                tree = replace(tree, params=r.scene_params)
            if on_progress:
                on_progress(path, "extracting")
            if r.params is None or not _same(r.params, tree.params):
                r = _read(replace(job(path), fresh=False, known=frozenset()))
            if isinstance(r.chain, SmcError):
                raise r.chain
            chain = r.chain
            assert chain is not None  # extracted: not known, no error
            for w in chain.warnings:
                warn(w)
            sources = [
                Source(log=path.name, sha256=r.sha256, t0=f.t0, t1=f.t1) for f in chain.fragments
            ]
            # A continuation taught during replay (smc replay --teach) grows the tree from
            # the node where no SMC was contingent.
            taught = r.metadata.get("teach_node")
            at = taught or ROOT
            if at not in tree.nodes:
                raise LogError(
                    f"{path}: taught at node {at} of tree {r.metadata.get('teach_tree', '?')}; "
                    f"{out} has no such node"
                )
            if at != ROOT and r.metadata.get("teach_tree_digest") != digest(tree):
                warn(
                    f"{path}: taught on another version of the tree (digest "
                    f"{r.metadata.get('teach_tree_digest', '?')[:19]}); inserted at {at}"
                )
            tree = insert_chain(tree, chain.smcs, sources, at=at)
            if not tree.scene:
                tree = replace(
                    tree,
                    scene={
                        "name": r.metadata.get("scene", ""),
                        "digest": r.metadata.get("scene_digest", ""),
                        "log": r.sha256,
                        "sensors": r.sensors,
                        "files": r.scene_files,
                        **(
                            {"path": r.metadata["scene_path"]}
                            if r.metadata.get("scene_path")
                            else {}
                        ),
                    },
                    robot=robot,
                )
            added.append(replace(chain, at=taught))
            layout = parse_layout(r.metadata.get("layout"))
            if layout is not None:
                layouts[chain.sha256] = layout
        if not added:
            return CompileResult(tree=tree, added=(), skipped=tuple(skipped), changed=False)
        entry = {
            "version": tree.version + 1,
            "time": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "smc_version": __version__,
            "logs": [
                {
                    "name": c.log.name,
                    "sha256": c.sha256,
                    "fragments": len(c.smcs),
                    **({"at": c.at} if c.at is not None else {}),
                    **({"layout": layouts[c.sha256]} if c.sha256 in layouts else {}),
                }
                for c in added
            ],
        }
        tree = replace(tree, version=tree.version + 1, history=(*tree.history, entry))
        save_tree(tree, out)
        return CompileResult(tree=tree, added=tuple(added), skipped=tuple(skipped), changed=True)
    finally:
        if pool is not None:
            # After an error: the logs still queued are dropped, those being read finish.
            pool.shutdown(wait=True, cancel_futures=True)
        lock.release()
