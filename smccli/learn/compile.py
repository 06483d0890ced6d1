"""``smc compile``: demonstration logs -> SMC chains -> the tree (paper 3.8, Algorithm 1).

Each log is read and its chain extracted (:mod:`smccli.learn.chain`), in worker processes or
in this one; then Algorithm 1 inserts the chains into the tree one at a time, in the order
the logs were given, and the tree is written atomically with a history entry.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import json
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from smccli import __version__
from smccli.errors import LogError, SmcError, TreeError
from smccli.learn.chain import Chain as Chain
from smccli.learn.chain import demonstration_warnings as demonstration_warnings
from smccli.learn.chain import extract_chain as extract_chain
from smccli.learn.chain import fragments as fragments
from smccli.learn.chain import required_topics as required_topics
from smccli.learn.chain import scene_params as scene_params
from smccli.learn.params import SmcParams, params_to_dict, with_overrides
from smccli.learn.segmentation import SegmentMode
from smccli.learn.smc import Source
from smccli.learn.tree import FORMAT, ROOT, Tree, digest, insert_chain, load_tree, save_tree
from smccli.logs import read_log
from smccli.logs import topics as tp
from smccli.logs.ros2_bag import ROLE_OF, ROLES, TopicMap, read_ros2_bag
from smccli.outputs import ExclusiveLock, check_output
from smccli.workers import clean_context
from smccli.world.scene import robot_identity, scene_of_log, sensor_identity


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
    """:func:`sensor_identity`."""
    scene_files: dict[str, str] = field(default_factory=dict)
    """The scene's files as the log carries them (``scene.yaml``, ``scene.xml``,
    ``robot.yaml``): the tree keeps its first log's, to run where it was taught."""
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
much as reading five logs (``compile --workers`` help says so)."""


def default_workers(n_logs: int) -> int:
    """Worker processes of a compile of ``n_logs`` logs by default: one per CPU this
    process may use, at most one per log; in process below :data:`PARALLEL_MIN_LOGS`."""
    if n_logs < PARALLEL_MIN_LOGS:
        return 1
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, min(cpus or 1, n_logs))


def _pool(workers: int) -> ProcessPoolExecutor:
    """Worker processes that start with this module imported (:mod:`smccli.workers`)."""
    return ProcessPoolExecutor(workers, mp_context=clean_context([__name__]))


WORKER_ENV = {"OPENBLAS_THREAD_TIMEOUT": "4"}
"""Environment of the worker processes, where the user has not set it. OpenBLAS's idle
threads spin for 2**28 cycles (~0.1 s) after every call before they sleep; with a worker
per core, each one's spinning threads take the others' cores. With 2**4 they sleep at
once. The DMP fit runs on one BLAS thread wherever it runs (smccli/learn/dmp.py), so the
tree does not depend on the thread count."""


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


@dataclass(slots=True)
class _Growing:
    """A compile under way: the tree as Algorithm 1 grows it, one chain at a time, and what
    was added or skipped so far."""

    out: Path
    """The tree file."""
    tree: Tree
    fresh: bool
    """The tree is new (absent, or ``--rebuild``): its first log's scene sets its
    perception settings."""
    overrides: tuple[str, ...]
    segment_mode: SegmentMode
    topic_map: TopicMap | None
    strict: bool
    known: frozenset[str]
    """Digests of the logs in the tree before this compile."""
    added: list[Chain] = field(default_factory=list)
    """Chains inserted, in order (``at``: where a taught one went)."""
    layouts: dict[str, dict[str, list[float]]] = field(default_factory=dict)
    """Log digest -> its recorded layout (:func:`parse_layout`)."""
    skipped: list[Path] = field(default_factory=list)

    def job(self, path: Path) -> _Job:
        """The job as the tree stands now: in process, exactly a sequential compile's."""
        return _Job(
            path,
            self.tree.params,
            self.fresh and not self.added,
            self.overrides,
            self.segment_mode,
            self.known | {c.sha256 for c in self.added},
            self.topic_map,
            self.strict,
        )

    def has(self, sha256: str) -> bool:
        """Whether the log of this digest is in the tree already (before or by this compile)."""
        return sha256 in self.known or any(c.sha256 == sha256 for c in self.added)


def _lock(out: Path) -> ExclusiveLock:
    """The tree's lock, held: one compile at a time writes ``out``."""
    lock = ExclusiveLock(f"{out}.lock")
    try:
        lock.acquire(timeout=60)
    except TimeoutError:
        raise TreeError(f"{out}: locked by another compile ({out}.lock)") from None
    return lock


def _open_tree(out: Path, rebuild: bool, overrides: Sequence[str]) -> tuple[Tree, bool]:
    """The tree the logs go into and whether it is fresh: the one at ``out``, whose
    parameters ``overrides`` must not change; else (absent, or ``rebuild``) a new one that
    keeps the version growing and the history of any tree it replaces."""
    if out.exists() and not rebuild:
        tree = load_tree(out)
        wanted = with_overrides(tree.params, list(overrides))
        if params_to_dict(wanted) != params_to_dict(tree.params):
            raise TreeError(
                f"{out}: --set {' '.join(overrides)} differs from the tree's "
                "parameters; use --rebuild to start afresh"
            )
        return tree, False
    version, history = _rebuild_base(out) if out.exists() else (0, ())
    params = with_overrides(SmcParams(), list(overrides))
    return Tree(params=params, version=version, history=history), True


@contextlib.contextmanager
def _reading(
    paths: Sequence[Path], n_workers: int, job: Callable[[Path], _Job]
) -> Iterator[Callable[[int], _Read]]:
    """``read(i)``: the ``i``-th log read and extracted. With several workers and logs, all
    are submitted at once, as the tree stands before the first log (a chain extracted with
    other parameters than the tree has when its turn comes is extracted again, in process);
    else each is read in process when asked, as the tree stands then. On leaving after an
    error, the logs still queued are dropped and those being read finish."""
    if n_workers <= 1 or len(paths) <= 1:
        yield lambda i: _read(job(paths[i]))
        return
    pool = _pool(n_workers)
    try:
        with _worker_env():  # the workers start on the first submits
            futures = [pool.submit(_read, job(p)) for p in paths]
        yield lambda i: _result(futures[i], paths[i])
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _check_fits(tree: Tree, r: _Read, path: Path) -> None:
    """LogError unless the log ``r`` fits ``tree``: its scene's model compiles, it was
    recorded with the tree's robot and in the tree's scene."""
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


def _chain(g: _Growing, r: _Read, path: Path) -> Chain:
    """The chain of log ``r``, extracted with the tree's parameters (again, in process, if
    a worker extracted it with others)."""
    if r.params is None or not _same(r.params, g.tree.params):
        r = _read(replace(g.job(path), fresh=False, known=frozenset()))
    if isinstance(r.chain, SmcError):
        raise r.chain
    assert r.chain is not None  # extracted: not known, no error
    return r.chain


def _insert(
    tree: Tree, chain: Chain, r: _Read, path: Path, out: Path, warn: Callable[[str], None]
) -> Tree:
    """Algorithm 1: ``chain`` inserted at the root, or a continuation taught during replay
    (``smc replay --teach``) at the node where no SMC was contingent; the first log's scene
    and robot become the tree's."""
    sources = [Source(log=path.name, sha256=r.sha256, t0=f.t0, t1=f.t1) for f in chain.fragments]
    at = r.metadata.get("teach_node") or ROOT
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
    if tree.scene:
        return tree
    scene = {
        "name": r.metadata.get("scene", ""),
        "digest": r.metadata.get("scene_digest", ""),
        "log": r.sha256,
        "sensors": r.sensors,
        "files": r.scene_files,
        **({"path": r.metadata["scene_path"]} if r.metadata.get("scene_path") else {}),
    }
    return replace(tree, scene=scene, robot=r.robot)


def _add(
    g: _Growing,
    r: _Read,
    path: Path,
    on_progress: Callable[[Path, str], None] | None,
    warn: Callable[[str], None],
) -> None:
    """One log's turn: refused (its error), skipped (in the tree already) or its chain
    inserted into ``g.tree``."""
    for w in r.warnings:
        warn(w)
    if r.error is not None:
        raise r.error
    if g.has(r.sha256):
        g.skipped.append(path)
        return
    _check_fits(g.tree, r, path)
    if g.fresh and not g.added:  # a new tree takes its scene's perception settings, then --set
        if isinstance(r.scene_params, SmcError):
            raise r.scene_params
        assert r.scene_params is not None  # computed for every fresh job
        g.tree = replace(g.tree, params=r.scene_params)
    if on_progress:
        on_progress(path, "extracting")
    chain = _chain(g, r, path)
    for w in chain.warnings:
        warn(w)
    g.tree = _insert(g.tree, chain, r, path, g.out, warn)
    g.added.append(replace(chain, at=r.metadata.get("teach_node")))
    layout = parse_layout(r.metadata.get("layout"))
    if layout is not None:
        g.layouts[chain.sha256] = layout


def _history_entry(g: _Growing) -> dict[str, Any]:
    """The tree's history entry for this compile: the new version, when, which smc, and
    each log added (its fragments, where a taught one went, its recorded layout)."""
    return {
        "version": g.tree.version + 1,
        "time": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "smc_version": __version__,
        "logs": [
            {
                "name": c.log.name,
                "sha256": c.sha256,
                "fragments": len(c.smcs),
                **({"at": c.at} if c.at is not None else {}),
                **({"layout": g.layouts[c.sha256]} if c.sha256 in g.layouts else {}),
            }
            for c in g.added
        ],
    }


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

    ``workers`` processes (default: :func:`default_workers`; 1: in this process) read the
    logs and extract their chains in parallel; the tree takes them in the order given
    (Algorithm 1 is sequential), so the tree, the warnings and the first error are those
    of a one-log-at-a-time compile.

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
    lock = _lock(out)
    try:
        tree, fresh = _open_tree(out, rebuild, overrides)
        g = _Growing(
            out,
            tree,
            fresh,
            tuple(overrides),
            segment_mode,
            topic_map,
            strict,
            frozenset(tree.log_digests()),
        )
        with _reading(paths, n_workers, g.job) as read:
            for i, path in enumerate(paths):
                if on_progress:
                    on_progress(path, "reading")
                _add(g, read(i), path, on_progress, warn)
        if not g.added:
            return CompileResult(tree=g.tree, added=(), skipped=tuple(g.skipped), changed=False)
        g.tree = replace(
            g.tree, version=g.tree.version + 1, history=(*g.tree.history, _history_entry(g))
        )
        save_tree(g.tree, out)
        return CompileResult(
            tree=g.tree, added=tuple(g.added), skipped=tuple(g.skipped), changed=True
        )
    finally:
        lock.release()
