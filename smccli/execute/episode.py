"""``smc replay``: one episode of an SMC tree in simulation (paper 3.6, 3.9, 5.1).

An episode loads the tree and the scene it runs in (:func:`resolve`), builds the layout
(:func:`layout_for`, :func:`~smccli.world.scene.load_layout_file`), runs Algorithm 2
through the robot's sensors
(:class:`~smccli.execute.executor.TreeExecutor` over
:class:`~smccli.execute.sensing.Sensors`), lets the scene settle at a leaf, and only then
scores it from the simulator's truth (:func:`smccli.execute.evaluation.score`).
Optionally it writes a replay log (:class:`~smccli.execute.replay_log.ReplayLog`) and a JSON
report.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from smccli.errors import OutputError, SceneError, SmcError, TreeError
from smccli.execute.evaluation import HandleWatch, score
from smccli.execute.executor import (
    LOOK_PERIOD,
    ActionTrace,
    Decision,
    TreeExecutor,
    check_look_period,
    check_speed,
)
from smccli.execute.replay_log import ReplayLog
from smccli.execute.sensing import Sensors
from smccli.execute.teach import TeachConfig, Teaching, check_teach
from smccli.execute.teach import teach as run_teaching
from smccli.learn.tree import Edge, Tree, digest, load_tree
from smccli.outputs import check_output, write_atomic
from smccli.world.layout import load_layout_file, sample_layout
from smccli.world.scene import (
    Layout,
    Scene,
    builtin_names,
    load_scene,
    robot_identity,
    scene_of_log,
    sensor_identity,
)
from smccli.world.sensors import PoiCommand
from smccli.world.sim import OdometryDrift, Sim
from smccli.world.truth import Push, Truth

FINAL_SETTLE = 1.0
"""Sim time the scene settles at a leaf before scoring [s]."""


@dataclass(frozen=True, slots=True)
class EpisodeResult:
    """Outcome and trace of one replay episode."""

    outcome: str
    """One of :data:`smccli.execute.evaluation.OUTCOMES`."""
    success: bool
    """The scene's success criterion at the end."""
    reason: str
    """Why: the success criterion's text, or what stopped control."""
    decisions: tuple[Decision, ...]
    actions: tuple[ActionTrace, ...]
    path: tuple[str, ...]
    """Edge ids taken."""
    layout: Layout
    """Object poses at the start."""
    duration: float
    """Sim time of the task: first decision to the last action's end [s]."""
    demo_duration: float
    """Sum of the source fragment durations of the path taken (mean per edge) [s]."""
    wall_time: float
    """Wall time of the episode [s]."""
    manipulated: str | None = None
    """The object the task moves (from the success criterion), for distance bands."""
    final_poses: dict[str, list[float]] = field(default_factory=dict)
    """Object [x, y, z, yaw] at the end (evaluation)."""
    criteria: tuple[tuple[str, str, bool], ...] = ()
    """Every success condition tried at the leaf: (task, what it found, whether it held)."""
    output: Path | None = None
    """The replay log written, if any."""
    note: str | None = None
    """Said about the run, e.g. that the scene is not the one the tree was taught in."""
    taught: Teaching | None = None
    """What an operator taught where no SMC was contingent (``teach``), if anything."""
    speed: float = 1.0
    """How many times faster than demonstrated the DMPs ran (``--speed``)."""

    @property
    def latencies_ms(self) -> list[float]:
        return [1e3 * d.latency_s for d in self.decisions]

    def to_report(self) -> dict[str, Any]:
        """The JSON report of ``--report``."""
        lat = self.latencies_ms
        return {
            "outcome": self.outcome,
            "success": self.success,
            "reason": self.reason,
            "path": list(self.path),
            "layout": {k: list(v) for k, v in self.layout.items()},
            "final_poses": self.final_poses,
            "decisions": [d.to_json() for d in self.decisions],
            "latency_ms": {
                "per_decision": lat,
                "p50": float(np.median(lat)) if lat else None,
                "max": max(lat) if lat else None,
            },
            "speed": self.speed,
            "duration_s": self.duration,
            "demo_duration_s": self.demo_duration,
            "duration_ratio": self.duration / self.demo_duration if self.demo_duration else None,
            "wall_time_s": self.wall_time,
            "output": None if self.output is None else str(self.output),
            "note": self.note,
            "taught": None
            if self.taught is None
            else {
                "node": self.taught.node,
                "log": str(self.taught.log),
                "tree_version": self.taught.version,
                "end": self.taught.end,
                "marks": self.taught.marks,
                "interrupted": self.taught.interrupted,
            },
        }


# --- the tree and scene ----------------------------------------------------------------


def resolve(tree_path: Path | Tree, scene: str | Path | Scene | None) -> tuple[Tree, Scene]:
    """Load the tree and the scene it runs in (default: the scene it was taught in).

    Another scene is accepted when it holds the same robot (name and kinematics) and the
    same sensors (:func:`check_fits`): a cluttered copy of the teaching scene is the common
    case; :func:`scene_note` says so. TreeError (one line) otherwise.
    """
    tree = tree_path if isinstance(tree_path, Tree) else load_tree(Path(tree_path))
    where = "tree" if isinstance(tree_path, Tree) else str(tree_path)
    if not tree.edges:
        raise TreeError(f"{where}: the tree holds no SMC (compile a demonstration first)")
    if scene is None:
        sc = taught_scene(tree, where)
    else:
        sc = scene if isinstance(scene, Scene) else load_scene(scene)
    check_fits(tree, sc, where)
    return tree, sc


def taught_scene(tree: Tree, where: str = "tree") -> Scene:
    """The scene the tree was taught in: the built-in one of its name when it is the same
    (digest), else the files the tree recorded from its first log (a scene of one's own,
    or a built-in one changed); SceneError when it has neither."""
    name = str(tree.scene.get("name", "")) if tree.scene else ""
    files = tree.scene.get("files") if tree.scene else None
    if name in builtin_names():
        builtin = load_scene(name)
        if not files or builtin.digest == tree.scene.get("digest"):
            return builtin
    if files:
        return scene_of_log({k: str(v).encode() for k, v in files.items()}, where)
    raise SceneError(
        f"{where}: built for scene {name!r}, which is not built in and which the tree does not "
        "record (compiled before trees kept their scene); pass --scene PATH"
    )


def check_fits(tree: Tree, scene: Scene, where: str = "tree") -> None:
    """TreeError unless ``scene`` holds the robot the tree was taught on and the sensors it
    perceives through (a scene other than the teaching one is fine then)."""
    tree_scene = str(tree.scene.get("name", "")) if tree.scene else ""
    if not tree.robot:  # a tree from before robot files: only its own scene is safe
        if tree_scene and scene.name != tree_scene:
            raise TreeError(
                f"{where}: built for scene {tree_scene!r}, not {scene.name!r} (the tree does "
                "not record its robot; compile it again with --rebuild to run it elsewhere)"
            )
        return
    model = scene.model()
    robot = robot_identity(scene, model)
    if robot != tree.robot:
        same = robot["name"] == tree.robot.get("name")
        raise TreeError(
            f"{where}: taught on robot {tree.robot.get('name')!r}; scene {scene.name} holds "
            + (
                f"a robot of that name with other kinematics ({robot['kinematics'][7:19]} "
                f"vs {str(tree.robot.get('kinematics'))[7:19]})"
                if same
                else f"robot {robot['name']!r}"
            )
            + "; a tree runs only on the robot it was taught on"
        )
    want = tree.scene.get("sensors")
    if want:
        have = sensor_identity(scene, model)
        if want.get("camera") != have["camera"]:
            a, b = want.get("camera", {}), have["camera"]
            raise TreeError(
                f"{where}: perceives through a {a.get('width')}x{a.get('height')} camera with a "
                f"{a.get('fovy'):g} deg field of view; scene {scene.name}'s is {b['width']}x"
                f"{b['height']}, {b['fovy']:g} deg"
            )
        if want.get("scale") and not have["scale"]:
            raise TreeError(f"{where}: perceives weight; scene {scene.name} has no scale")


def scene_note(tree: Tree, scene: Scene) -> str | None:
    """A note when the tree runs in a scene other than the one it was taught in."""
    tree_scene = str(tree.scene.get("name", "")) if tree.scene else ""
    if tree_scene and scene.name != tree_scene:
        return (
            f"taught in scene {tree_scene!r}, running in {scene.name!r} "
            f"(same robot {scene.robot.name!r} and sensors)"
        )
    taught = str(tree.scene.get("digest", "")) if tree.scene else ""
    if taught and scene.digest != taught:
        return (
            f"taught in another version of scene {tree_scene!r} (digest {taught[:19]}), "
            f"running in {scene.digest[:19]} (same robot {scene.robot.name!r} and sensors)"
        )
    path = Path(str(tree.scene.get("path", ""))) if tree.scene else None
    if scene.yaml_path is None and path is not None and path.is_file():
        # The tree's own copy runs; the file it came from was edited since.
        try:
            changed = load_scene(path).digest != scene.digest
        except SmcError:
            changed = True
        if changed:
            return (
                f"running scene {tree_scene!r} as it was taught; {path} has changed since "
                "(--scene to run it as it is now)"
            )
    return None


def layout_for(scene: Scene, seed: int, trial: int = 0) -> Layout:
    """The layout of trial ``trial`` of a campaign with ``seed`` (an episode is trial 0)."""
    return sample_layout(scene, np.random.default_rng([seed, trial]))


# --- episodes -----------------------------------------------------------------------------


def demo_duration(path: Sequence[Edge]) -> float:
    """Sum over the edges taken of their source fragments' mean duration [s]. A tree
    compiled with idle trimming (``params.idle``) records the trimmed fragments: this is
    then the demonstrated motion, without the waiting at fragment boundaries."""
    return float(sum(np.mean([s.t1 - s.t0 for s in e.sources]) for e in path if e.sources))


@dataclass(frozen=True, slots=True)
class _Control:
    """What control did in an episode, before evaluation."""

    outcome: str
    reason: str
    decisions: list[Decision]
    actions: list[ActionTrace]
    path: list[Edge]
    duration: float
    """Sim time of the task [s] (:attr:`EpisodeResult.duration`)."""
    taught: Teaching | None


class _Harness:
    """The episode's own hand and eyes beside control, once per control period: the
    disturbance (``push``), evaluation's watch (what a mobile base touches, a handle that
    leaves the closed hand) and the replay log. It reads the truth; control never sees it."""

    def __init__(self, sim: Sim, scene: Scene, push: Push | None) -> None:
        self.sim, self.scene, self.push = sim, scene, push
        self.truth = Truth(sim)
        self.touched: set[str] = set()
        """What a mobile base touched (the floor aside)."""
        self.slips = HandleWatch(scene.doors)
        self.log: ReplayLog | None = None
        self._pushed = False

    def on_step(self, cmd: PoiCommand) -> None:
        """One control period: ``cmd`` was sent and the simulator stepped."""
        push = self.push
        if push is not None and not self._pushed and self.sim.t >= push.at:
            self.truth.push_object(push.object, push.dx, push.dy)  # the world, not control
            self._pushed = True
        if self.scene.robot.base is not None:
            self.touched.update(self.truth.robot_contacts())
        if self.scene.doors:
            self.slips.watch(self.truth, cmd)
        if self.log is not None:
            self.log.on_step(cmd)

    def close_log(self) -> None:
        if self.log is not None:
            self.log.close()
            self.log = None


def episode(
    tree: Tree,
    scene: Scene,
    layout: Layout,
    *,
    seed: int = 0,
    output: Path | None = None,
    force: bool = False,
    evaluate: Callable[[Sim], None] | None = None,
    drift: OdometryDrift | None = None,
    teach: TeachConfig | None = None,
    speed: float = 1.0,
    sim: Sim | None = None,
    push: Push | None = None,
    look_period: float = LOOK_PERIOD,
) -> EpisodeResult:
    """Run Algorithm 2 once on ``layout`` and score it. ``evaluate`` runs first thing after
    control (tests use it to re-enable object queries); ``drift``: a mobile base's odometry
    error (:class:`~smccli.world.sim.OdometryDrift`); ``teach``: where no SMC is
    contingent, an operator continues from there, the tree file grows from that node and
    execution goes on from where the taught chain ends (:mod:`smccli.execute.teach`; the
    replay log holds the autonomous part before it); ``speed``: every DMP that many times
    faster (the caller checks it, :func:`~smccli.execute.executor.check_speed`); ``sim``:
    a simulator of ``scene`` with ``drift`` to reset and keep open, instead of building
    one (campaign workers keep theirs: its renderer's GL context and the compiled model
    are most of a trial's setup; a reset gives the state a new simulator would); ``push``:
    someone moves an object while the robot works (a disturbance, for benchmarks);
    ``look_period``: how often an arm looks again at what it acts on (0: never)."""
    wall0 = time.perf_counter()
    own = sim is None
    if sim is None:
        sim = Sim(scene, layout, drift=drift)
    else:
        if sim.scene is not scene or sim.drift != drift:
            raise ValueError("episode: the simulator given runs another scene or drift")
        sim.reset(layout)
    harness = _Harness(sim, scene, push)
    try:
        if output is not None:
            harness.log = ReplayLog(Path(output), scene, sim, tree, seed, layout, force)
        run = _control(tree, sim, harness, teach, seed, speed, look_period)
    except BaseException:
        if harness.log is not None:
            harness.log.abort()
        raise
    finally:
        if own:
            sim.close()
    # --- evaluation: control is over, the simulator may be read ---
    if evaluate is not None:
        evaluate(sim)
    verdict = score(
        sim,
        scene,
        layout,
        outcome=run.outcome,
        reason=run.reason,
        actions=run.actions,
        collisions=sorted(harness.touched),
        slips=harness.slips.slipped,
    )
    return EpisodeResult(
        outcome=verdict.outcome,
        success=verdict.success,
        reason=verdict.reason,
        decisions=tuple(run.decisions),
        actions=tuple(run.actions),
        path=tuple(e.id for e in run.path),
        layout=layout,
        duration=run.duration,
        demo_duration=demo_duration(run.path),
        wall_time=time.perf_counter() - wall0,
        manipulated=verdict.manipulated,
        final_poses=verdict.final_poses,
        criteria=verdict.criteria,
        output=None if output is None else Path(output),
        taught=run.taught,
        speed=speed,
    )


def _control(
    tree: Tree,
    sim: Sim,
    harness: _Harness,
    teach: TeachConfig | None,
    seed: int,
    speed: float,
    look_period: float,
) -> _Control:
    """Algorithm 2 through the robot's sensors until a leaf or a stop; with ``teach``, an
    operator continues where no SMC is contingent and execution goes on after the taught
    chain. At a leaf reached with success, the scene settles (:data:`FINAL_SETTLE`). The
    replay log is closed when control ends (before teaching, if an operator takes over)."""
    log = harness.log
    sensors = Sensors(sim, on_step=harness.on_step)
    sim.start_camera()  # the camera is running before the task starts (GL warm-up)
    executor = TreeExecutor(
        tree,
        sensors,
        on_decision=None if log is None else log.on_decision,
        speed=speed,
        look_period=look_period,
    )
    t0 = sim.t
    outcome, reason, decisions, actions, path = executor.run()
    taught = None
    if teach is not None and outcome == "no_contingent_smc":
        harness.close_log()
        taught = run_teaching(sim, tree, executor.policy.nodes[0], teach, seed)
        executor = TreeExecutor(
            load_tree(teach.tree_path), sensors, speed=speed, look_period=look_period
        )
        outcome, reason, more_d, more_a, more_p = executor.run(start=taught.end)
        decisions, actions, path = decisions + more_d, actions + more_a, path + more_p
    # The task ends with its last action: the retreat after a last release
    # (executor.RETREAT) is clearing away, as the demonstration's after its last mark.
    duration = (actions[-1].t1 if outcome == "success" and actions else sim.t) - t0
    if outcome == "success":
        for _ in range(round(FINAL_SETTLE / sim.control_period)):
            executor.hold()
    harness.close_log()
    return _Control(outcome, reason, decisions, actions, path, duration, taught)


def run_episode(
    tree: Path | Tree,
    *,
    scene: str | Path | Scene | None = None,
    seed: int = 0,
    layout: Path | Layout | None = None,
    output: Path | None = None,
    report: Path | None = None,
    force: bool = False,
    drift: OdometryDrift | None = None,
    teach: TeachConfig | None = None,
    speed: float = 1.0,
    look_period: float = LOOK_PERIOD,
) -> EpisodeResult:
    """``smc replay TREE``: one episode on the layout file or the seed's layout (trial 0);
    ``teach``: an operator continues where no SMC is contingent (``--teach``); ``speed``:
    every DMP that many times faster (``--speed``); ``look_period``: how often an arm looks
    again at what it acts on (``--look-period`` [s], 0: never).

    Raises TreeError/SceneError (exit 2) for a bad tree or scene, SmcError (exit 2) for a
    speed beyond the tree's limit, OutputError before any work when an output cannot be
    written (or exists without ``force``).
    """
    if output is not None and report is not None and Path(output) == Path(report):
        raise OutputError(f"{output}: given as both the replay log and the report")
    for out in (output, report):
        if out is not None:
            check_output(out, force=force)
    t, sc = resolve(tree, scene)
    check_speed(t, speed)
    check_look_period(look_period)
    if layout is None:
        lay = layout_for(sc, seed)
    elif isinstance(layout, dict):
        lay = layout
    else:
        lay = load_layout_file(Path(layout), sc)
    if teach is not None:
        check_teach(teach)
    result = episode(
        t,
        sc,
        lay,
        seed=seed,
        output=output,
        force=force,
        drift=drift,
        teach=teach,
        speed=speed,
        look_period=look_period,
    )
    result = replace(result, note=scene_note(t, sc))
    if report is not None:
        doc = {
            "tree": str(tree) if not isinstance(tree, Tree) else None,
            "tree_digest": digest(t),
            "scene": sc.name,
            "seed": seed,
            **result.to_report(),
        }
        write_atomic(report, json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return result
