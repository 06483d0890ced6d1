"""``smc record``: an operator drives the robot in a scene; everything goes into an MCAP log.

The loop runs at the control rate (100 Hz of simulation time): the operator gives a POI
command, the Cartesian controller tracks it, and the log receives the command, joint
states, POI, scale reading and ground truth every tick and the RGB-D camera at its rate.
The log is written as ``NAME.mcap.part`` (flushed every second) and renamed on a clean
finish, so a crash loses at most the last second and never leaves a half-written
``NAME.mcap``.
"""

from __future__ import annotations

import json
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from smccli import __version__
from smccli.errors import ScriptError
from smccli.logs import LogWriter, log_summary
from smccli.logs.writer import scene_attachments
from smccli.outputs import check_output
from smccli.world.layout import nominal_layout, sample_layout
from smccli.world.scene import Layout, Scene, load_scene
from smccli.world.sim import Sim
from smccli.world.truth import Truth

if TYPE_CHECKING:
    from smccli.record.keyboard import KeyboardOperator
    from smccli.record.operators import Script, ScriptOperator

MAX_DURATION = 600.0
"""A recording longer than this [s of sim time] is stopped as a runaway script."""


@dataclass(frozen=True, slots=True)
class RecordConfig:
    """What to record."""

    scene: str
    """Built-in scene name or path to a scene.yaml."""
    operator: str = "script"
    """``script`` or ``keyboard``."""
    script: Path | None = None
    """Teleop script for the script operator."""
    seed: int = 0
    """Seed of the operator's noise (and of the layout with ``randomize``)."""
    output: Path = Path("demo.mcap")
    """Log to write."""
    force: bool = False
    """Overwrite an existing log."""
    randomize: bool = False
    """Start from a random layout of the scene instead of the nominal one."""
    ground_truth_rate: float = 10.0
    """Rate of ``/sim/ground_truth`` [Hz] (evaluation only)."""
    realtime: bool = False
    """Pace the script operator at real time, as a person would (keyboard: always)."""
    reproducible: bool = False
    """Cut chunks on simulation time only, so the same script and seed give a byte-identical
    file (sample logs); otherwise also every wall-clock second, for crash safety."""
    episodes: int = 1
    """Demonstrations in the session (:func:`record_episodes`)."""


@dataclass(frozen=True, slots=True)
class RecordStatus:
    """Live status, reported every few ticks."""

    t: float
    """Simulation time [s]."""
    messages: int
    """Messages written so far."""
    marks: int
    """Saliency marks so far."""
    t_on_disk: float = 0.0
    """Simulation time [s] up to which the log is on disk (survives a crash)."""


@dataclass(frozen=True, slots=True)
class RecordSummary:
    """What was recorded."""

    path: Path
    """The log written."""
    duration: float
    """Simulation time recorded [s]."""
    wall_time: float
    """Wall-clock time spent [s]."""
    fragments: int
    """Fragments marked by the operator (= marks)."""
    topics: dict[str, tuple[int, float]]
    """Topic -> (message count, rate [Hz])."""
    size_bytes: int
    """File size [bytes]."""
    interrupted: str | None = None
    """Why the recording stopped early (``SIGINT``, ``SIGTERM``), or None if it finished."""
    task: dict | None = None
    """The log's task verdict (``smc_end``): ``{success, reason, criteria}``."""
    scene: Scene | None = None
    """The scene recorded in."""

    @property
    def failed_task(self) -> bool:
        """Whether the recorder judged that the demonstration failed its scene's task (a
        scene without a task, or a verdict not checked, is not a failure); ``smc record``
        then exits 1 unless ``--allow-failed``."""
        return self.task is not None and self.task.get("success") is False


def _metadata(scene: Scene, cfg: RecordConfig, extra: dict[str, str]) -> dict[str, str]:
    return {
        "scene": scene.name,
        "scene_digest": scene.digest,
        "robot": scene.robot.name,
        "smc_version": __version__,
        "seed": str(cfg.seed),
        "operator": cfg.operator,
        "control_rate_hz": "100",
        "state_rate_hz": "100",
        "camera_rate_hz": f"{scene.camera.rate:g}",
        "has_scale": "true" if scene.scale else "false",
        # Where the scene file was: replay notes when it changed after the tree was taught.
        **({"scene_path": str(scene.yaml_path.resolve())} if scene.yaml_path else {}),
        **extra,
    }


def episode_paths(output: Path, episodes: int) -> list[Path]:
    """The logs of a session: ``output`` itself for one episode, else ``NAME-000.mcap``,
    ``NAME-001.mcap``, ... beside it."""
    if episodes == 1:
        return [Path(output)]
    output = Path(output)
    return [output.with_name(f"{output.stem}-{i:03d}{output.suffix}") for i in range(episodes)]


def record(
    cfg: RecordConfig,
    on_status: Callable[[RecordStatus], None] | None = None,
    on_message: Callable[[str], None] | None = None,
) -> RecordSummary:
    """Record one demonstration into ``cfg.output``; see the module docstring.

    SIGINT or SIGTERM (when called from the main thread) end the recording cleanly: the log
    is kept, marked ``interrupted`` in its ``smc_end`` metadata, and the summary says so.
    Only the operator's explicit discard, or an error in a teleop script (which re-records
    the same demonstration), removes the log; any other failure keeps what was recorded.
    """
    return record_episodes(replace(cfg, episodes=1), on_status, on_message)[0]


def record_episodes(
    cfg: RecordConfig,
    on_status: Callable[[RecordStatus], None] | None = None,
    on_message: Callable[[str], None] | None = None,
) -> list[RecordSummary]:
    """Record ``cfg.episodes`` demonstrations in one session (:func:`episode_paths`), one
    simulation and one viewer throughout; returns the summaries of the logs kept.

    Episode ``i`` uses seed ``cfg.seed + i`` for the operator's noise and (``randomize``)
    its layout, so it is the demonstration ``smc record --seed SEED+i`` would record alone;
    else every episode starts from the nominal layout. A person ends an episode with Enter
    (keep it, go on), X (discard it: the same episode is recorded again from the same
    layout) or Esc (keep it and end the session); closing the viewer, SIGINT or SIGTERM
    keep the episode and end the session. ``on_message`` gets a status line between
    episodes. Every log's path is checked before the first episode starts.
    """
    if cfg.episodes < 1:
        raise ScriptError(f"--episodes must be at least 1, found {cfg.episodes}")
    outs = [check_output(p, force=cfg.force) for p in episode_paths(cfg.output, cfg.episodes)]
    scene = load_scene(cfg.scene)
    extra: dict[str, str] = {}
    script, layout_of = _layouts(cfg, scene, extra)
    say = on_message or (lambda msg: None)
    sim = Sim(scene, layout_of(cfg.seed), target_marker=cfg.operator == "keyboard")
    keyboard: KeyboardOperator | None = None
    summaries: list[RecordSummary] = []
    try:
        if cfg.operator == "keyboard":
            from smccli.record.keyboard import KeyboardOperator

            keyboard = KeyboardOperator(sim, on_ready=say)
        i = 0
        while i < cfg.episodes:
            layout = layout_of(cfg.seed + i)
            summary = _record_episode(
                sim, i, layout, cfg, outs[i], extra, script, keyboard, on_status, say
            )
            if summary is None:  # discarded: record it again
                continue
            summaries.append(replace(summary, scene=scene))
            if _episode_kept(summary, i, cfg, keyboard, say):
                break
            i += 1
    finally:
        # The sensor renderer's GL context first, then the viewer: the viewer's thread
        # tears GLFW down, and a context freed after that crashes the process.
        sim.close()
        if keyboard is not None:
            keyboard.close()
    return summaries


def _layouts(
    cfg: RecordConfig, scene: Scene, extra: dict[str, str]
) -> tuple[Script | None, Callable[[int], Layout]]:
    """The operator's script (None for the keyboard) and the layout of each episode's seed;
    the script's name goes into ``extra`` (the log's metadata)."""
    if cfg.operator == "script":
        from smccli.record.operators import load_script, script_layout

        if cfg.script is None:
            raise ScriptError("--operator script needs --script FILE")
        script = load_script(cfg.script)
        extra["script"] = Path(cfg.script).name

        def scripted(seed: int) -> Layout:
            return script_layout(scene, script, _rng(seed) if cfg.randomize else None)

        return script, scripted
    if cfg.operator == "keyboard":
        first = scene.variants[0][0] if scene.variants else None

        def by_hand(seed: int) -> Layout:
            if cfg.randomize:
                return sample_layout(scene, _rng(seed))
            return nominal_layout(scene, first)

        return None, by_hand
    raise ScriptError(f"unknown operator {cfg.operator!r} (valid: script, keyboard)")


def _record_episode(
    sim: Sim,
    i: int,
    layout: Layout,
    cfg: RecordConfig,
    out: Path,
    extra: dict[str, str],
    script: Script | None,
    keyboard: KeyboardOperator | None,
    on_status: Callable[[RecordStatus], None] | None,
    say: Callable[[str], None],
) -> RecordSummary | None:
    """Episode ``i`` of the session from ``layout`` into ``out``; None when the person
    discarded it (it is then recorded again)."""
    from smccli.record.operators import ScriptOperator

    seed = cfg.seed + i
    sim.reset(layout)
    if keyboard is not None:
        keyboard.reset((i + 1, cfg.episodes) if cfg.episodes > 1 else None)
        operator: ScriptOperator | KeyboardOperator = keyboard
    else:
        assert script is not None
        operator = ScriptOperator(script, sim, seed=seed)
    ep = replace(cfg, seed=seed)
    ep_extra = {
        **extra,
        **({"episode": f"{i + 1}/{cfg.episodes}"} if cfg.episodes > 1 else {}),
        # Where the objects started (reports only: a campaign's distance bands).
        "layout": json.dumps({k: [float(x) for x in v] for k, v in layout.items()}),
    }
    wall0 = time.perf_counter()
    try:
        marks, interrupted = record_session(sim, operator, ep, out, ep_extra, on_status)
    except ScriptError:
        if keyboard is None or not keyboard.discarded:
            raise
        if cfg.episodes == 1:
            raise
        say(f"episode {i + 1}/{cfg.episodes} discarded; recording it again")
        return None
    return _summary(out, sim.t, time.perf_counter() - wall0, marks, interrupted)


def _episode_kept(
    summary: RecordSummary,
    i: int,
    cfg: RecordConfig,
    keyboard: KeyboardOperator | None,
    say: Callable[[str], None],
) -> bool:
    """Tell the person episode ``i`` was kept (and its task's verdict); whether the
    session ends with it."""
    verdict = task_line(summary.task)
    if keyboard is not None:
        keyboard.last_task = verdict
    last = i + 1 == cfg.episodes
    ended = summary.interrupted is not None or (
        keyboard is not None and (keyboard.stopped or not keyboard.window_open)
    )
    if cfg.episodes > 1:
        left = "session ended" if ended or last else f"next: episode {i + 2}/{cfg.episodes}"
        say(
            f"episode {i + 1}/{cfg.episodes} kept: {summary.path} ({summary.duration:.1f} s, "
            f"{summary.fragments} mark(s){'; ' + verdict if verdict else ''}); {left}"
        )
    return ended


def _summary(
    out: Path, duration: float, wall: float, marks: int, interrupted: str | None
) -> RecordSummary:
    summary = log_summary(out)
    task = _task(out)
    return RecordSummary(
        path=out,
        duration=duration,
        wall_time=wall,
        fragments=marks,
        topics={k: (int(v["count"]), float(v["rate_hz"])) for k, v in summary["topics"].items()},
        size_bytes=out.stat().st_size,
        interrupted=interrupted,
        task=task,
    )


def _task(out: Path) -> dict | None:
    """The task verdict the log's ``smc_end`` record holds (:func:`task_outcome`)."""
    from smccli.logs import read_log

    return read_log(out, topics=()).task


def record_session(
    sim: Sim,
    operator: ScriptOperator | KeyboardOperator,
    cfg: RecordConfig,
    out: Path,
    extra: dict[str, str],
    on_status: Callable[[RecordStatus], None] | None = None,
) -> tuple[int, str | None]:
    """Record ``operator`` driving ``sim`` from the state it is in into ``out`` (checked by
    the caller); ``extra`` metadata beside the recorder's. Returns (marks written, why the
    recording was interrupted or None). A script's error or the operator's discard
    removes the log; any other failure keeps what was recorded."""
    writer = LogWriter(
        out,
        metadata=_metadata(sim.scene, cfg, extra),
        attachments=scene_attachments(sim.scene),
        force=cfg.force,
        wall_clock_flush=not cfg.reproducible,
    )
    try:
        with _stop_requests() as stop:
            marks = _session(writer, sim, operator, cfg, stop, on_status)
    except ScriptError:
        writer.abort()  # the script's fault (or the operator's discard): re-record it
        raise
    except BaseException as exc:
        writer.close(interrupted=f"error: {exc.__class__.__name__}")
        raise
    interrupted = stop[0] if stop else None
    writer.close(interrupted=interrupted, end_fields={"task": task_outcome(sim)})
    return marks, interrupted


TASK_SETTLE = 0.5
"""Sim time the scene settles after a demonstration before its task is checked [s]."""


def task_line(task: dict | None) -> str | None:
    """The task verdict in a few words (HUD, session messages); None without one."""
    if not task or task.get("success") is None:
        return None
    return "task achieved" if task["success"] else f"task FAILED: {task.get('reason', '?')}"


def task_outcome(sim: Sim) -> str:
    """Whether the demonstration achieved its task, as evaluation judges an episode (the
    simulator's truth, after the scene settles): JSON ``{success, reason, criteria}`` for
    the log's ``smc_end`` record. Compile reads only this verdict (a warning, or a refusal
    with ``--strict``), never the truth itself."""
    if not sim.scene.success:
        return json.dumps({"success": None, "reason": "the scene defines no task"})
    try:
        sim.settle(TASK_SETTLE)
        s = Truth(sim).success()
    except Exception as exc:  # the check must never cost the recording its end record
        return json.dumps({"success": None, "reason": f"not checked: {exc}"})
    criteria = [list(c) for c in s.criteria]
    return json.dumps({"success": bool(s.ok), "reason": s.reason, "criteria": criteria})


def _session(
    writer: LogWriter,
    sim: Sim,
    operator: ScriptOperator | KeyboardOperator,
    cfg: RecordConfig,
    stop: list[str],
    on_status: Callable[[RecordStatus], None] | None,
) -> int:
    """The recording loop, until the operator is done or ``stop`` holds a signal's name.

    Returns the number of saliency marks written.
    """
    marks = 0
    cam_period = 1.0 / sim.scene.camera.rate
    gt_period = 1.0 / cfg.ground_truth_rate
    next_cam = next_gt = 0.0
    truth = Truth(sim)  # the evaluation topic alone
    tick = 0
    _log_state(writer, sim)
    frame = sim.render_camera()
    _log_cloud(writer, sim, frame)  # what the robot saw as the demonstration began
    t_wall0 = time.perf_counter()
    while not stop:
        t = sim.t
        if cfg.realtime and cfg.operator == "script":
            ahead = t - (time.perf_counter() - t_wall0)
            if ahead > 0:
                time.sleep(ahead)
        if t >= next_cam - 1e-9:
            frame = sim.render_camera() if t > 0 else frame
            writer.write_camera(frame)
            writer.write_lidar(sim)  # the lidar runs on the camera's clock
            next_cam += cam_period
        if t >= next_gt - 1e-9:
            writer.write_ground_truth(t, truth.ground_truth())
            next_gt += gt_period
        step = operator.tick()
        for mark in step.marks:
            writer.write_saliency(mark)
            marks += 1
        if step.marks and sim.scene.camera.at_marks and frame.t < sim.t - 1e-9:
            # A slow camera also looks at each decision point, where compile perceives.
            frame = sim.render_camera()
            writer.write_camera(frame)
            writer.write_lidar(sim)
        if step.marks:  # the scene at each salient moment, for inspection
            _log_cloud(writer, sim, frame)
        if step.done:
            break
        writer.write_command(step.command)
        sim.step(step.command)
        _log_state(writer, sim)
        tick += 1
        if on_status and tick % 10 == 0:
            on_status(
                RecordStatus(
                    t=sim.t,
                    messages=sum(writer.counts.values()),
                    marks=marks,
                    t_on_disk=writer.t_on_disk,
                )
            )
        if sim.t > MAX_DURATION:
            if cfg.operator == "script":  # a runaway script: fix it and record again
                raise ScriptError(
                    f"{cfg.script}: recording passed {MAX_DURATION:.0f} s of simulation "
                    "time; stopped"
                )
            stop.append(f"time limit {MAX_DURATION:.0f} s")  # a person's work: keep it
            break
    if getattr(operator, "discarded", False):
        raise ScriptError("recording discarded by the operator; nothing written")
    return marks


@contextmanager
def _stop_requests() -> Iterator[list[str]]:
    """SIGINT and SIGTERM append their name to the yielded list instead of raising.

    The loop checks the list once per tick, so a signal never lands in the middle of a
    write and the log can be closed cleanly. Outside the main thread (where Python cannot
    install handlers) the list stays empty and signals behave as usual.
    """
    stop: list[str] = []
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return

    def handler(signum: int, _frame: object) -> None:
        stop.append(signal.Signals(signum).name)

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def _log_state(writer: LogWriter, sim: Sim) -> None:
    t = sim.t
    writer.write_joint_state(sim.joint_state())
    writer.write_robot_pose(sim)
    w = sim.weight()
    if w is not None:
        writer.write_weight(t, w)


def _log_cloud(writer: LogWriter, sim: Sim, frame) -> None:
    """World-frame point cloud of the workspace (robot removed) on ``/perception/points``."""
    from smccli.perception import cloud_from_frame
    from smccli.perception.params import scene_perception

    base = sim.base_odometry() if sim.mobile_manipulator else None
    params = scene_perception(sim.scene)
    points, colors = cloud_from_frame(frame, sim.robot_geometry(), params, base=base)
    writer.write_point_cloud(sim.t, points[::2].astype("float32"), colors[::2])


def _rng(seed: int):
    import numpy as np

    return np.random.default_rng(seed)
