"""The honesty rule, audited while it runs: during control, the robot sees the simulator only
through its sensors and its joint encoders (docs/design.md section 2).

One episode per kind of robot (an arm, a mobile base, a mobile manipulator) runs on a
simulator that records every attribute read on it, with the module that read it. Control
(the executor, the policy, perception, what compile learnt) must read nothing; the sensing
facade only the sensor readings listed here; the episode's harness only its setup and the
clock. The truth (:mod:`smccli.world.truth`) is out of control's reach by an import rule
(``tests/test_layout.py``). And no object control holds, at any depth, is the simulator,
its model or its data.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

import smccli.execute.episode as episode_module  # noqa: E402
from smccli.execute.episode import episode, layout_for, resolve  # noqa: E402
from smccli.execute.executor import TreeExecutor  # noqa: E402
from smccli.learn.compile import compile_logs  # noqa: E402
from smccli.world.sim import Sim  # noqa: E402

SAMPLES = Path(__file__).resolve().parent.parent / "sample_logs"

SENSOR_READINGS = {
    # sensors and encoders
    "poi",
    "base_odometry",
    "gripper_opening",
    "gripper_speed",
    "joint_state",
    "weight",
    "lidar",
    "lidar_pose",
    "render_camera",
    "robot_geometry",
    # the camera's calibration: where a frame's pixels look, before rendering it
    "camera_matrix",
    "camera_pose",
    "camera_near",
    # the camera driver's capability: whether it reads a window of the image alone
    "camera_windows",
    # the command input, the clock and the files the robot was built from
    "step",
    "t",
    "control_period",
    "robot",
    "scene",
    "mobile_manipulator",
}
"""What :class:`smccli.execute.sensing.Sensors` may read on the simulator."""
HARNESS = {"smccli.execute.episode", "smccli.execute.evaluation"}
"""The episode's own loop and evaluation's watch beside control (what a base touches,
whether a handle slips from the hand)."""
HARNESS_READS = {"scene", "drift", "reset", "start_camera", "control_period", "t"}
"""What the harness reads on the simulator itself while control runs: its setup and the
clock. The truth it watches goes through :class:`smccli.world.truth.Truth` (reads of the
simulator's own package, not audited here), which no control module imports, directly or
not (``tests/test_layout.py``)."""


class AuditedSim(Sim):
    """A simulator that records ``(module, attribute)`` for every attribute read on it from
    outside the simulator's own package while :attr:`watching`."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        object.__setattr__(self, "reads", [])
        object.__setattr__(self, "watching", False)
        super().__init__(*args, **kwargs)

    def __getattribute__(self, name: str) -> Any:
        if not name.startswith("__") and object.__getattribute__(self, "watching"):
            module = sys._getframe(1).f_globals.get("__name__", "?")
            if not module.startswith("smccli.world"):
                object.__getattribute__(self, "reads").append((module, name))
        return object.__getattribute__(self, name)


def _violations(reads: list[tuple[str, str]]) -> set[tuple[str, str]]:
    """The reads that break the rule: by the facade beyond the sensor readings, by the
    harness beyond its setup and clock, or by any other module."""
    allowed = {"smccli.execute.sensing": SENSOR_READINGS} | dict.fromkeys(HARNESS, HARNESS_READS)
    return {(module, name) for module, name in reads if name not in allowed.get(module, ())}


def _holds(root: Any, targets: dict[int, str], skip: set[tuple[int, str]]) -> list[str]:
    """Paths from ``root`` (attributes, items) to any object whose id is in ``targets``,
    not following the attributes ``skip`` names as ``(id(owner), name)``."""
    found, seen, todo = [], set(), [(root, "executor")]
    while todo:
        obj, path = todo.pop()
        if id(obj) in targets:
            found.append(f"{path} is the simulator's {targets[id(obj)]}")
            continue
        if id(obj) in seen or isinstance(obj, (str, bytes, int, float, np.ndarray, type)):
            continue
        seen.add(id(obj))
        if isinstance(obj, dict):
            todo += [(v, f"{path}[{k!r}]") for k, v in obj.items()]
        elif isinstance(obj, (list, tuple, set, frozenset)):
            todo += [(v, f"{path}[{i}]") for i, v in enumerate(obj)]
        elif isinstance(obj, (mujoco.MjModel, mujoco.MjData)):
            continue
        else:
            fields = getattr(obj, "__dict__", {})
            slots = [s for c in type(obj).__mro__ for s in getattr(c, "__slots__", ())]
            todo += [(v, f"{path}.{k}") for k, v in fields.items() if (id(obj), k) not in skip]
            todo += [(getattr(obj, s), f"{path}.{s}") for s in slots if hasattr(obj, s)]
            if callable(obj) and getattr(obj, "__closure__", None):
                todo += [(c.cell_contents, f"{path}.<closure>") for c in obj.__closure__]
    return found


@pytest.fixture(scope="module")
def trees(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("honesty")
    out = {}
    for scene in ("bench_pick", "rooms", "loco_manip"):
        out[scene] = root / f"{scene}.json"
        compile_logs(sorted((SAMPLES / scene).glob("*.mcap")), out[scene])
    return out


@pytest.mark.parametrize(
    "scene_name, kind",
    [("bench_pick", "arm"), ("rooms", "mobile base"), ("loco_manip", "mobile manipulator")],
)
def test_control_reads_only_sensors_and_encoders(trees, monkeypatch, scene_name, kind):
    tree, scene = resolve(trees[scene_name], None)
    layout = layout_for(scene, 3)
    sim = AuditedSim(scene)
    executors: list[TreeExecutor] = []

    class Recorded(TreeExecutor):
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            executors.append(self)

    monkeypatch.setattr(episode_module, "TreeExecutor", Recorded)
    object.__setattr__(sim, "watching", True)
    reads_at_end: list[tuple[str, str]] = []

    def control_over(s: Sim) -> None:
        reads_at_end.extend(object.__getattribute__(s, "reads"))
        object.__setattr__(s, "watching", False)

    result = episode(tree, scene, layout, sim=sim, evaluate=control_over)
    assert result.outcome == "success", (kind, result.reason)
    assert reads_at_end, "the audit saw the facade read the sensors"
    facade = {name for module, name in reads_at_end if module == "smccli.execute.sensing"}
    assert facade <= SENSOR_READINGS, f"{kind}: the facade read {facade - SENSOR_READINGS}"
    assert {"render_camera" if kind != "mobile base" else "lidar", "step", "poi"} <= facade
    others = _violations(reads_at_end)
    assert not others, f"{kind}: control read the simulator: {sorted(others)}"

    # No path from what control holds leads to the simulator's state, except the
    # facade's own handle on it and the harness's per-step callback it calls.
    (executor,) = executors
    sensors = executor.sensors
    targets = {id(sim): "self", id(sim.model): "model", id(sim.data): "data"}
    skip = {(id(sensors), "_sim"), (id(sensors), "_on_step")}
    assert _holds(executor, targets, skip) == []
    # Its model is the scene compiled from its files: where the layout put things is not
    # in it (loco_manip's wardrobe, rooms' poster, bench_pick's objects).
    nominal = scene.model()
    np.testing.assert_array_equal(sensors.model.body_pos, nominal.body_pos)
    np.testing.assert_array_equal(sensors.model.body_quat, nominal.body_quat)
    if scene.furniture:
        b = sim.model.body(scene.furniture[0].name).id
        assert not np.array_equal(sim.model.body_pos[b], sensors.model.body_pos[b])


def test_the_audit_catches_a_read_of_the_simulator(trees, monkeypatch):
    """The audit itself: a policy that peeks at the simulator's data through the facade is
    reported (the test above cannot pass by seeing nothing)."""
    import smccli.execute.sensing as sensing

    tree, scene = resolve(trees["bench_pick"], None)
    sim = AuditedSim(scene)
    peek = sensing.Sensors.poi

    def peeking_poi(self):  # what a dishonest change would write
        _ = self._sim.data.xpos
        return peek(self)

    monkeypatch.setattr(sensing.Sensors, "poi", peeking_poi)
    object.__setattr__(sim, "watching", True)
    episode(tree, scene, layout_for(scene, 3), sim=sim, evaluate=lambda s: None)
    assert (__name__, "data") in _violations(object.__getattribute__(sim, "reads"))


def test_control_never_reads_where_the_demonstrations_started() -> None:
    """The tree's history keeps each demonstration's start layout for the campaign's
    distance bands: the simulator's truth about the demonstration. No control module
    touches the history (the executor, the policy, the matching, the sensing facade)."""
    import ast

    root = Path(__file__).resolve().parent.parent / "smccli"
    control = [root / "execute" / f"{m}.py" for m in ("executor", "policy", "sensing")] + [
        root / "learn" / "contingency.py",
        *sorted((root / "perception").glob("*.py")),
    ]
    for path in control:
        tree = ast.parse(path.read_text(encoding="utf-8"))
        reads = [
            n.lineno
            for n in ast.walk(tree)
            if (isinstance(n, ast.Attribute) and n.attr == "history")
            or (isinstance(n, ast.Constant) and n.value == "history")
        ]
        assert not reads, f"{path}: reads the tree's history at lines {reads}"
