"""The scripted operator: a teleop script (YAML) played by a simulated person.

The format is documented in ``schemas/teleop_script.schema.json``. The simulated operator
looks at an object's pose when a step starts (it is a person watching the scene, not the
robot), moves the POI target along a minimum-jerk path

    s(τ) = 10τ³ − 15τ⁴ + 6τ⁵,   τ = (t − t₀) / T ∈ [0, 1],

adds optional tremor, hesitation pauses and speed variation drawn from
``numpy.random.default_rng(seed)``, and presses the saliency button on ``mark`` steps.
Same script, scene, layout and seed: the same command stream.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from smccli.errors import ScriptError, SmcError
from smccli.schemas import SchemaProblem, YamlDocument, check_yaml, key_path, parse_yaml
from smccli.world.controller import ARRIVAL_TOLERANCE, home_poi, reach_problem
from smccli.world.geometry import between, compose, near, wrap
from smccli.world.layout import nominal_layout, sample_layout
from smccli.world.scene import ROBOT_KEY, Layout, Scene, load_scene
from smccli.world.sensors import PoiCommand, SaliencyMark
from smccli.world.sim import Sim
from smccli.world.truth import Truth

TREMOR_TIME_CONSTANT = 0.15
"""Correlation time of the tremor noise [s]."""
MIN_MOVE_TIME = 0.5
"""Shortest move [s]."""


@dataclass(frozen=True, slots=True)
class Step:
    """One operator step of a script."""

    kind: str
    """``move_to``, ``gripper``, ``mark`` or ``wait``."""
    index: int
    """Position in the script's ``steps`` list (0-based)."""
    line: int
    """Line of the step in the YAML file (1-based)."""
    object: str | None = None
    """move_to: object the target is relative to, or None for an absolute position."""
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """move_to: POI offset in the object's yawed frame [m]."""
    position: tuple[float, float, float] | None = None
    """move_to: absolute POI position [m] (when ``object`` is None)."""
    yaw: float | None = None
    """move_to: yaw [rad], relative to the object's or absolute; None keeps the current yaw."""
    duration: float | None = None
    """move_to: duration [s]; None means from distance and speed."""
    gripper: float = 1.0
    """gripper: opening in [0, 1] (1 = open)."""
    label: str = ""
    """mark: the mark's label."""
    seconds: float = 0.0
    """wait: how long [s]."""
    place: str | None = None
    """move_to from a ``go_to`` step: the scene's named place [x, y, yaw] to drive to."""
    base: str | tuple[float, float, float] | None = None
    """move_to of a mobile manipulator: where its base goes in the same move (a place's
    name or ``(x, y, yaw)``); None: the base stays."""
    home: bool = False
    """move_to from a ``home`` step: the hand to the robot's home posture (base frame)."""
    hand: tuple[float, float, float] | None = None
    """move_to ``hand``: a mobile manipulator's hand position in its base's frame [m]."""

    def where(self, source: str) -> str:
        return f"{source}: step {self.index} (line {self.line}, {self.kind})"


@dataclass(frozen=True, slots=True)
class Script:
    """A parsed, schema-valid teleop script."""

    source: str
    """File path, or ``<text>`` when parsed from a string."""
    text: str
    """The YAML text, verbatim (logs embed it)."""
    scene: str
    """Scene the script is written for."""
    steps: tuple[Step, ...]
    """The steps, in order."""
    speed: float = 0.15
    """Nominal mean speed of a move [m/s]."""
    yaw_speed: float = 1.0
    """Nominal mean yaw rate of a move [rad/s]."""
    tremor: float = 0.0
    """Standard deviation of the position tremor [m]."""
    hesitation: float = 0.0
    """Probability of a pause before each move."""
    speed_variation: float = 0.0
    """Relative spread of move durations."""
    description: str = ""
    """What the demonstration shows."""
    variant: str | None = None
    """Scene variant (object subset) the demonstration is recorded in; None: the default."""
    start: tuple[float, float, float] | None = None
    """A mobile base's start pose ``(x, y, yaw)`` [m, m, rad]; None: the scene's (or a
    random one with ``smc record --random-layout``)."""


@dataclass(frozen=True, slots=True)
class OperatorOutput:
    """What the operator does in one control tick."""

    command: PoiCommand
    """Command for the next control period."""
    marks: tuple[SaliencyMark, ...] = ()
    """Saliency marks pressed in this tick."""
    done: bool = False
    """True once every step is finished (the command then holds the last pose)."""


def load_script(path: str | Path) -> Script:
    """Read and validate a teleop script; ScriptError names the file, step and line."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise ScriptError(f"{p}: cannot read teleop script: {exc.strerror}") from exc
    return parse_script(text, str(p))


def parse_script(text: str, source: str = "<text>") -> Script:
    """Parse and validate a teleop script given as YAML text (``schemas/teleop_script``)."""
    doc = parse_yaml(text, source, ScriptError)
    check_yaml(doc, "teleop_script", ScriptError, where=_step_where)
    raw = doc.data
    steps = tuple(_step(s, i, doc.line(("steps", i)) or 0) for i, s in enumerate(raw["steps"]))
    return Script(
        source=source,
        text=text,
        scene=str(raw["scene"]),
        steps=steps,
        speed=float(raw.get("speed", 0.15)),
        yaw_speed=float(raw.get("yaw_speed", 1.0)),
        tremor=float(raw.get("tremor", 0.0)),
        hesitation=float(raw.get("hesitation", 0.0)),
        speed_variation=float(raw.get("speed_variation", 0.0)),
        description=str(raw.get("description", "")),
        variant=None if raw.get("variant") is None else str(raw["variant"]),
        start=None if raw.get("start") is None else tuple(float(v) for v in raw["start"]),  # type: ignore[arg-type]
    )


def _step_where(problem: SchemaProblem, doc: YamlDocument) -> str | None:
    """``step 3 (line 12)`` for a problem inside a step (the wording of :meth:`Step.where`),
    then the key path within the step and its own line when that differs."""
    path = problem.path
    if len(path) < 2 or path[0] != "steps" or not isinstance(path[1], int):
        return None
    line = doc.line(path[:2])
    out = f"step {path[1]} (line {line})"
    if len(path) > 2:
        out += f": {key_path(path[2:])}"
        if problem.line is not None and problem.line != line:
            out += f" (line {problem.line})"
    return out


def _step(raw: dict[str, Any], index: int, line: int) -> Step:
    kind = next(iter(raw))
    value = raw[kind]
    if kind == "move_to":
        return Step(
            kind,
            index,
            line,
            object=value.get("object"),
            offset=tuple(float(v) for v in value.get("offset", (0, 0, 0))),  # type: ignore[arg-type]
            position=(
                tuple(float(v) for v in value["position"])  # type: ignore[arg-type]
                if "position" in value
                else None
            ),
            hand=(
                tuple(float(v) for v in value["hand"])  # type: ignore[arg-type]
                if "hand" in value
                else None
            ),
            yaw=float(value["yaw"]) if "yaw" in value else (0.0 if "object" in value else None),
            duration=float(value["duration"]) if "duration" in value else None,
            base=(
                None
                if value.get("base") is None
                else value["base"]
                if isinstance(value["base"], str)
                else tuple(float(v) for v in value["base"])  # type: ignore[arg-type]
            ),
        )
    if kind == "go_to":  # a mobile base to a named place: a move_to resolved at start
        spec = {"place": value} if isinstance(value, str) else value
        duration = float(spec["duration"]) if "duration" in spec else None
        return Step("move_to", index, line, place=str(spec["place"]), duration=duration)
    if kind == "home":
        duration = None if not value or "duration" not in value else float(value["duration"])
        return Step("move_to", index, line, home=True, duration=duration)
    if kind == "gripper":
        opening = {"open": 1.0, "close": 0.0}.get(value, value)
        return Step(kind, index, line, gripper=float(opening))
    if kind == "mark":
        return Step(kind, index, line, label="" if value is None else str(value))
    return Step(kind, index, line, seconds=float(value))


def minimum_jerk(tau: float) -> float:
    """Minimum-jerk progress s(τ) for τ clipped to [0, 1]."""
    t = min(1.0, max(0.0, tau))
    return t**3 * (10 - 15 * t + 6 * t**2)


@dataclass(slots=True)
class _Active:
    """Plan of the step being executed (mutable operator state)."""

    step: Step
    t0: float
    start: np.ndarray = field(default_factory=lambda: np.zeros(4))
    goal: np.ndarray = field(default_factory=lambda: np.zeros(4))
    pause: float = 0.0
    duration: float = 0.0
    still_ticks: int = 0
    base_start: np.ndarray | None = None
    """A mobile manipulator's base path (odometry frame ``[x, y, yaw]``), start and goal."""
    base_goal: np.ndarray | None = None
    world_start: np.ndarray | None = None
    """Its end effector's path in the world (None: it rides with the base)."""
    world_goal: np.ndarray | None = None


class ScriptOperator:
    """Plays a :class:`Script` on a :class:`Sim`, one control tick at a time.

    Usage::

        op = ScriptOperator(script, sim, seed=0)
        while not (out := op.tick()).done:
            sim.step(out.command)
    """

    def __init__(self, script: Script, sim: Sim, seed: int = 0) -> None:
        if not _names_scene(script, sim.scene):
            raise ScriptError(
                f"{script.source}: written for scene {script.scene!r}, "
                f"but the simulation runs {sim.scene.name!r}"
            )
        truth = Truth(sim)  # a person sees where things are
        names = [o.name for o in sim.scene.objects if o.name in sim.present]
        places = [n for n, _ in sim.scene.places]
        for step in script.steps:
            for place in (step.place, step.base if isinstance(step.base, str) else None):
                if place is not None and place not in places:
                    raise ScriptError(
                        f"{step.where(script.source)}: no place {place!r} in scene "
                        f"{sim.scene.name} (places: {', '.join(places) or 'none'})"
                    )
            key = "base" if step.base is not None else "hand" if step.hand is not None else None
            if key is not None and not sim.mobile_manipulator:
                raise ScriptError(
                    f"{step.where(script.source)}: {key}: is for a mobile manipulator; "
                    f"scene {sim.scene.name}'s robot {sim.robot.name!r} is not one"
                )
            # A mobile manipulator's operator also grasps the scene's furniture (a door's
            # handle is a body of the scene's MJCF, not a listed object).
            if (
                step.object is not None
                and step.object not in names
                and not (sim.mobile_manipulator and truth.has_body(step.object))
            ):
                raise ScriptError(
                    f"{step.where(script.source)}: no object {step.object!r} in scene "
                    f"{sim.scene.name} as laid out (objects: {', '.join(names)})"
                )
        self.script = script
        self.sim = sim
        self.truth = truth
        self.rng = np.random.default_rng(seed)
        self._i = 0
        self._active: _Active | None = None
        self._target = sim.poi()  # the hand starts where the robot is
        self._base = sim.base_odometry() if sim.mobile_manipulator else None
        """A mobile manipulator's base target (its ``_target`` is in the base's frame)."""
        self._gripper = sim.gripper_opening()
        self._tremor = np.zeros(3)
        self._a = math.exp(-sim.control_period / TREMOR_TIME_CONSTANT)

    @property
    def done(self) -> bool:
        return self._i >= len(self.script.steps)

    def tick(self) -> OperatorOutput:
        """The command for the next control period, marks pressed now, and whether done."""
        t = self.sim.t
        marks: list[SaliencyMark] = []
        while not self.done:
            if self._active is None:
                self._active = self._start(self.script.steps[self._i], t)
                if self._active.step.kind == "mark":
                    marks.append(SaliencyMark(t, "operator", self._active.step.label))
            if self._advance(self._active, t):
                self._active = None
                self._i += 1
                continue
            break
        return OperatorOutput(self._command(t), tuple(marks), self.done)

    def _command(self, t: float) -> PoiCommand:
        target = self._target.copy()
        if self.script.tremor > 0:
            # AR(1) low-pass noise with stationary std = tremor.
            a = self._a
            self._tremor = a * self._tremor + math.sqrt(1 - a * a) * self.script.tremor * (
                self.rng.standard_normal(3)
            )
            target[:3] += self._tremor
        base = None if self._base is None else self._base.copy()
        return PoiCommand(t=t, target=target, gripper=self._gripper, base=base)

    def _start(self, step: Step, t: float) -> _Active:
        act = _Active(step, t)
        if step.kind != "move_to":
            return act
        if self._base is not None:
            return self._start_mobile(act)
        goal = self._home() if step.home else self._goal(step)
        problem = reach_problem(self.sim.model, self.sim.robot, goal)
        if problem is not None:
            raise ScriptError(
                f"{step.where(self.script.source)}: target "
                f"[{goal[0]:.3f}, {goal[1]:.3f}, {goal[2]:.3f}] m, yaw {goal[3]:.2f} rad "
                f"is out of the robot's reach: {problem}"
            )
        act.start = self._target.copy()
        # Turn the short way from the current command (the controller wraps too).
        goal[3] = act.start[3] + wrap(goal[3] - act.start[3])
        act.goal = goal
        dist = float(np.linalg.norm(goal[:3] - act.start[:3]))
        duration = step.duration or max(
            MIN_MOVE_TIME,
            dist / self.script.speed,
            abs(goal[3] - act.start[3]) / self.script.yaw_speed,
        )
        v = self.script.speed_variation
        hesitate = self.rng.uniform() < self.script.hesitation
        scale = self.rng.uniform(1 - v, 1 + v)  # always drawn: keeps the stream aligned
        pause = self.rng.uniform(0.2, 0.6)
        act.duration = duration * (scale if step.duration is None else 1.0)
        act.pause = pause if hesitate else 0.0
        return act

    def _start_mobile(self, act: _Active) -> _Active:
        """A mobile manipulator's move: the base to its goal (``go_to``, ``base``), the end
        effector to its world goal (``object``, ``position``), both on one clock."""
        step = act.step
        assert self._base is not None
        b0 = self._base.copy()
        where = step.place if step.place is not None else step.base
        if where is None:
            b1 = b0.copy()
        else:
            b1 = np.array(self.sim.scene.place(where) if isinstance(where, str) else where)
            b1[2] = b0[2] + wrap(float(b1[2] - b0[2]))
        act.base_start, act.base_goal = b0, b1
        if step.home or step.hand is not None:  # in the base's frame, the base still
            if step.home:
                act.goal = self._home()
            else:
                yaw = self._target[3] if step.yaw is None else step.yaw
                act.goal = np.array([*step.hand, yaw])  # type: ignore[misc]
            # The parallel gripper is symmetric under a half turn: the wrist turns the
            # short way to either of the two yaws.
            act.goal[3] = near(float(act.goal[3]), float(self._target[3]), math.pi)
        elif step.place is None:  # the hand moves in the world
            act.world_start = compose(b0, self._target)
            act.world_goal = self._goal(step, base=b1)
            act.world_goal[3] = act.world_start[3] + wrap(act.world_goal[3] - act.world_start[3])
            act.goal = between(b1, act.world_goal)
        else:  # it rides with the base
            act.goal = self._target.copy()
        act.start = self._target.copy()
        problem = reach_problem(self.sim.model, self.sim.robot, act.goal)
        if problem is not None:
            g = act.goal
            raise ScriptError(
                f"{step.where(self.script.source)}: target [{g[0]:.3f}, {g[1]:.3f}, "
                f"{g[2]:.3f}] m, yaw {g[3]:.2f} rad in the base's frame is out of reach: "
                f"{problem}"
            )
        arm = (
            0.0
            if act.world_start is None
            else float(
                np.linalg.norm(act.world_goal[:3] - act.world_start[:3])  # type: ignore[index]
            )
        )
        turn = abs(b1[2] - b0[2])
        duration = step.duration or max(
            MIN_MOVE_TIME,
            arm / self.script.speed,
            float(np.linalg.norm(b1[:2] - b0[:2])) / self.script.speed,
            turn / self.script.yaw_speed,
        )
        v = self.script.speed_variation
        hesitate = self.rng.uniform() < self.script.hesitation
        scale = self.rng.uniform(1 - v, 1 + v)
        pause = self.rng.uniform(0.2, 0.6)
        act.duration = duration * (scale if step.duration is None else 1.0)
        act.pause = pause if hesitate else 0.0
        return act

    def _home(self) -> np.ndarray:
        """The hand's pose at the robot's home posture, in the base's (model's) frame."""
        return home_poi(self.sim.model, self.sim.robot)

    def _goal(self, step: Step, base: np.ndarray | None = None) -> np.ndarray:
        if step.place is not None:
            x, y, yaw = self.sim.scene.place(step.place)
            return np.array([x, y, 0.0, yaw])
        if step.object is not None:
            x, y, z, oyaw = self.truth.object_pose(step.object)
            c, s = math.cos(oyaw), math.sin(oyaw)
            dx, dy, dz = step.offset
            goal = np.array(
                [x + c * dx - s * dy, y + s * dx + c * dy, z + dz, oyaw + (step.yaw or 0)]
            )
        else:
            assert step.position is not None
            yaw = self._target[3] if step.yaw is None else step.yaw
            goal = np.array([*step.position, yaw])
        if self.sim.robot.gripper is None:  # a mobile base: its heading is what it is
            return goal
        # The gripper is symmetric under a half turn: take the yaw (mod π) nearest the
        # wrist's comfortable yaw, which points along the arm (base yaw = atan2(y, x), in
        # the base's frame for a mobile manipulator).
        local = goal if base is None else between(base, goal)
        comfort = math.atan2(local[1], local[0]) + (0.0 if base is None else float(base[2]))
        if base is not None and self._gripper < 0.5 and self._base is not None:
            # Holding a handle, a person turns the wrist with it, never round by half a turn.
            comfort = float(compose(self._base, self._target)[3])
        goal[3] = comfort + wrap(2 * (goal[3] - comfort)) / 2
        return goal

    def _advance(self, act: _Active, t: float) -> bool:
        """Update the command for ``act`` at time ``t``; True when the step is finished."""
        step, elapsed = act.step, t - act.t0
        if step.kind == "mark":
            return True
        if step.kind == "wait":
            return elapsed >= step.seconds - 1e-9
        if step.kind == "gripper":
            self._gripper = step.gripper
            # Finished when the fingers have stopped (on the object or at the end stop).
            moving = abs(self.sim.gripper_speed()) > 0.02
            act.still_ticks = 0 if moving else act.still_ticks + 1
            return (elapsed > 0.15 and act.still_ticks >= 10) or elapsed > 3.0
        tau = (elapsed - act.pause) / act.duration
        s = minimum_jerk(tau)
        if act.base_start is not None and act.base_goal is not None:
            self._base = act.base_start + s * (act.base_goal - act.base_start)
        if act.world_start is not None and act.world_goal is not None and self._base is not None:
            hand = act.world_start + s * (act.world_goal - act.world_start)
            self._target = between(self._base, hand)
        else:  # in the robot's frame (a go_to's hand rides along: start = goal)
            self._target = act.start + s * (act.goal - act.start)
        if tau < 1.0:
            return False
        arrived = bool(np.linalg.norm(self.sim.poi()[:3] - act.goal[:3]) < ARRIVAL_TOLERANCE)
        if act.base_goal is not None:
            odom = self.sim.base_odometry()
            arrived = arrived and float(np.linalg.norm(odom[:2] - act.base_goal[:2])) < 0.01
        return bool(arrived or tau * act.duration > act.duration + 1.0)


def run_script(script: Script, sim: Sim, seed: int = 0, *, max_time: float = 600.0):
    """Play ``script`` to the end; yields each tick's :class:`OperatorOutput` after stepping."""
    op = ScriptOperator(script, sim, seed)
    while True:
        out = op.tick()
        sim.step(out.command)
        yield out
        if out.done:
            return
        if sim.t > max_time:
            raise ScriptError(f"{script.source}: still running after {max_time:.0f} s")


def _names_scene(script: Script, scene: Scene) -> bool:
    """Whether the script's ``scene:`` is ``scene``: its name, or its scene.yaml, a relative
    path read from the script's folder (as the script's author wrote it)."""
    if script.scene == scene.name:
        return True
    given = Path(script.scene)
    if not given.is_absolute() and script.source:
        given = Path(script.source).parent / given
    if scene.yaml_path is None:
        # The scene a tree carries (replay --teach without --scene) has no file: the
        # script's scene file, where it still is, names it when it is the same scene.
        if not given.is_file():
            return False
        try:
            return load_scene(given).digest == scene.digest
        except SmcError:
            return False
    return given.resolve() == Path(scene.yaml_path).resolve() or script.scene == str(
        scene.yaml_path
    )


def script_layout(scene: Scene, script: Script, rng: np.random.Generator | None = None) -> Layout:
    """The layout a script is played in: its variant, nominal, or sampled with ``rng``."""
    variant = script.variant
    if variant is None and scene.variants:
        variant = scene.variants[0][0]
    layout = (
        nominal_layout(scene, variant)
        if rng is None
        else sample_layout(scene, rng, variant=variant)
    )
    if script.start is not None:
        if scene.robot.base is None:
            raise ScriptError(
                f"{script.source}: start: a start pose is for a mobile base; scene "
                f"{scene.name}'s robot {scene.robot.name!r} has none"
            )
        x, y, yaw = script.start
        layout[ROBOT_KEY] = (x, y, 0.0, yaw)
    return layout
