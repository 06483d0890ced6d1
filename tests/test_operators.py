"""Scripted operator: sample scripts succeed in sim, determinism, grasp holds, script errors."""

from __future__ import annotations

from pathlib import Path

import jsonschema
import numpy as np
import pytest
import yaml
from test_scene import fields_without_description

from smccli.errors import ScriptError
from smccli.record.operators import (
    ScriptOperator,
    load_script,
    minimum_jerk,
    parse_script,
    run_script,
    script_layout,
)
from smccli.schemas import load_schema
from smccli.world.scene import load_scene
from smccli.world.sim import Sim
from smccli.world.truth import Truth

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = sorted((ROOT / "sample_logs").glob("*/*.yaml"))
# rooms and loco_manip: tests/test_rooms.py, tests/test_loco_manip.py
ARM_SAMPLES = [p for p in SAMPLES if p.parent.name not in ("rooms", "loco_manip")]
EXPECTED_MARKS = {
    "demo1": ["grasp", "release"],
    "demo2": ["grasp", "release"],
    "demo": ["grasp", "release"],
    "demo_light": ["grasp", "on_scale", "regrasp", "place"],
    "demo_heavy": ["grasp", "on_scale", "regrasp", "place"],
}


def test_sample_scripts_are_schema_valid() -> None:
    schema = load_schema("teleop_script")
    jsonschema.Draft202012Validator.check_schema(schema)
    assert len(SAMPLES) == 10
    for path in SAMPLES:
        jsonschema.validate(yaml.safe_load(path.read_text()), schema)
        assert load_script(path).steps


def test_script_schema_describes_every_field_and_refuses_unknown_keys() -> None:
    schema = load_schema("teleop_script")
    assert fields_without_description(schema, schema) == []


@pytest.mark.parametrize("path", ARM_SAMPLES, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_sample_script_succeeds(path: Path) -> None:
    script = load_script(path)
    scene = load_scene(script.scene)
    sim = Sim(scene, script_layout(scene, script))
    marks = []
    for out in run_script(script, sim, seed=0):
        for mark in out.marks:
            marks.append((mark, sim.poi().copy(), sim.gripper_opening(), Truth(sim).ground_truth()))
    assert [m[0].label for m in marks] == EXPECTED_MARKS[path.stem]
    assert marks[0][0].source == "operator" and marks[0][2] < 0.9  # closed on the object
    for mark, poi, _, truth in marks:
        # Each fragment ends with the POI at the salient object (held or just released).
        nearest = min(np.linalg.norm(poi[:3] - p[:3]) for p in truth.values())
        assert nearest < 0.06, mark.label
    sim.settle(1.0)
    result = Truth(sim).success()
    assert result, result.reason


def test_weigh_demos_read_different_weights() -> None:
    weights = {}
    for stem in ("demo_light", "demo_heavy"):
        script = load_script(ROOT / "sample_logs" / "weigh_sort" / f"{stem}.yaml")
        scene = load_scene("weigh_sort")
        sim = Sim(scene, script_layout(scene, script, np.random.default_rng(1)))
        for out in run_script(script, sim, seed=1):
            if any(m.label == "on_scale" for m in out.marks):
                weights[stem] = sim.weight()
                break
    assert weights["demo_light"] == pytest.approx(0.1, abs=0.005)
    assert weights["demo_heavy"] == pytest.approx(0.5, abs=0.005)


SHORT = """\
scene: pick_place
tremor: 0.002
hesitation: 0.5
speed_variation: 0.3
steps:
  - move_to: {object: orange_cube, offset: [0, 0, 0.1], yaw: 0.5}
  - mark: here
  - move_to: {position: [0.4, 0.1, 0.2]}
  - wait: 0.2
"""


def _stream(seed: int) -> list[tuple]:
    script = parse_script(SHORT)
    sim = Sim(load_scene("pick_place"))
    out = []
    for tick in run_script(script, sim, seed=seed):
        c = tick.command
        out.append((c.t, tuple(c.target), c.gripper, tuple(m.label for m in tick.marks)))
    return out


def test_same_seed_same_commands() -> None:
    a, b, c = _stream(3), _stream(3), _stream(4)
    assert a == b
    assert a != c


def test_minimum_jerk_profile() -> None:
    assert minimum_jerk(0.0) == 0.0 and minimum_jerk(1.0) == 1.0
    assert minimum_jerk(0.5) == pytest.approx(0.5)
    s = [minimum_jerk(t) for t in np.linspace(0, 1, 50)]
    assert np.all(np.diff(s) >= 0)


def test_grasp_holds_during_a_fast_move() -> None:
    script = parse_script(
        """\
scene: weigh_sort
variant: heavy
steps:
  - move_to: {object: heavy_box, offset: [0, 0, 0.1]}
  - move_to: {object: heavy_box, offset: [0, 0, 0]}
  - gripper: close
  - move_to: {position: [0.45, 0.35, 0.3], yaw: 1.0, duration: 0.6}
  - move_to: {position: [0.55, -0.3, 0.15], yaw: -0.5, duration: 0.6}
"""
    )
    scene = load_scene("weigh_sort")
    sim = Sim(scene, script_layout(scene, script))
    offsets = []
    moving = False
    for _ in run_script(script, sim):
        moving = moving or sim.poi()[2] > 0.1 and sim.gripper_opening() < 0.9
        if moving:
            offsets.append(
                np.linalg.norm(Truth(sim).ground_truth()["heavy_box"][:3] - sim.poi()[:3])
            )
    assert offsets and max(offsets) < 0.01  # 0.5 kg box stays between the fingers


def _err(text: str) -> str:
    with pytest.raises(ScriptError) as info:
        parse_script(text, "bad.yaml")
    return str(info.value)


def test_schema_errors_name_step_and_line() -> None:
    msg = _err("scene: pick_place\nsteps:\n  - wait: 1\n  - grip: close\n")
    assert "bad.yaml: step 1 (line 4)" in msg and "exactly one of" in msg
    msg = _err("scene: pick_place\nsteps:\n  - gripper: half\n")
    assert "step 0 (line 3)" in msg
    msg = _err("scene: pick_place\nsteps:\n  - move_to: {object: orange_cube, offset: [0, 0]}\n")
    assert "step 0 (line 3)" in msg and "move_to" in msg
    assert "not valid YAML" in _err("scene: [\n")
    assert "steps" in _err("scene: pick_place\n")
    assert _err("scene: pick_place\nsteps: []\n") == (
        "bad.yaml: steps (line 2): expected at least 1 item, found 0: []"
    )
    with pytest.raises(ScriptError, match="nothere.yaml"):
        load_script("nothere.yaml")


def test_unknown_object_names_step_and_line() -> None:
    script = parse_script(
        "scene: pick_place\nsteps:\n  - wait: 0.1\n  - move_to: {object: blue_whale}\n", "s.yaml"
    )
    with pytest.raises(ScriptError, match=r"s.yaml: step 1 \(line 4.*blue_whale.*orange_cube"):
        ScriptOperator(script, Sim(load_scene("pick_place")))


def test_unreachable_target_names_step_and_line() -> None:
    script = parse_script(
        "scene: pick_place\nsteps:\n  - mark: a\n  - move_to: {position: [1.5, 0, 0.2]}\n", "s.yaml"
    )
    sim = Sim(load_scene("pick_place"))
    with pytest.raises(
        ScriptError, match=r"s.yaml: step 1 \(line 4, move_to\).*out of the robot's reach"
    ):
        list(run_script(script, sim))


def test_scene_mismatch() -> None:
    script = parse_script("scene: weigh_sort\nsteps:\n  - wait: 0.1\n")
    with pytest.raises(ScriptError, match="weigh_sort.*pick_place"):
        ScriptOperator(script, Sim(load_scene("pick_place")))


@pytest.mark.parametrize(
    "steps, expected",
    [
        (
            "  - move_to: {object: orange_cube, ofset: [0, 0, 0.1]}\n",
            "step 0 (line 3): move_to.ofset: unknown key 'ofset' (valid: object, offset, yaw, "
            "duration, base)",
        ),
        (
            "  - wait: 1\n  - move_to:\n      object: orange_cube\n      offset: [0, 0, high]\n",
            "step 1 (line 4): move_to.offset[2] (line 6): expected a number, found 'high'",
        ),
        (
            "  - gripper: 1.5\n",
            "step 0 (line 3): gripper: expected 'open' or 'close' or a number in [0, 1], found 1.5",
        ),
        (
            "  - move_to: {object: orange_cube, position: [0.4, 0, 0.2]}\n",
            "step 0 (line 3): move_to: expected exactly one of the keys object, hand, position, "
            "found object, position",
        ),
        (
            "  - {wait: 1, mark: a}\n",
            "step 0 (line 3): expected exactly one of the keys move_to, go_to, gripper, mark, "
            "wait, home, found wait, mark",
        ),
        ("  - wait\n", "step 0 (line 3): expected a mapping with one of the keys move_to, "),
        ("  - wait: -1\n", "step 0 (line 3): wait: expected a number in [0, 60], found -1"),
    ],
)
def test_step_errors_name_the_key_path(steps: str, expected: str) -> None:
    msg = _err("scene: pick_place\nsteps:\n" + steps)
    assert msg.startswith("bad.yaml: ") and expected in msg, msg


def test_top_level_errors_name_key_and_line() -> None:
    assert _err("scene: pick_place\nsped: 0.2\nsteps:\n  - wait: 1\n") == (
        "bad.yaml: sped (line 2): unknown key 'sped' (valid: scene, description, variant, speed, "
        "yaw_speed, tremor, hesitation, speed_variation, steps, start)"
    )
    assert _err("scene: pick_place\nspeed: fast\nsteps:\n  - wait: 1\n") == (
        "bad.yaml: speed (line 2): expected a number, found 'fast'"
    )
    assert (
        _err("- wait: 1\n")
        == "bad.yaml: top level (line 1): expected a mapping, found [{'wait': 1}]"
    )


def test_variant_null_means_the_default() -> None:
    script = parse_script("scene: pick_place\nvariant: null\nsteps:\n  - wait: 1\n")
    assert script.variant is None and script.steps[0].line == 4


def test_a_scripts_scene_path_names_the_scene_a_tree_carries(tmp_path: Path) -> None:
    """replay --teach without --scene runs the scene the tree keeps (no file): a script
    whose ``scene:`` is a path still names it when that file holds the same scene, and
    not once the file changed."""
    from smccli.record.operators import _names_scene, load_script
    from smccli.world.scene import load_scene_from_text

    src = Path(__file__).resolve().parent / "scenes" / "mug_place"
    folder = tmp_path / "mug"
    folder.mkdir()
    for name in ("scene.yaml", "scene.xml"):
        (folder / name).write_text((src / name).read_text())
    script_text = (src / "demo.yaml").read_text()
    first = next(line for line in script_text.splitlines() if line.startswith("scene:"))
    (folder / "demo.yaml").write_text(script_text.replace(first, "scene: scene.yaml"))
    on_disk = load_scene(folder / "scene.yaml")
    carried = load_scene_from_text(on_disk.yaml_text, on_disk.mjcf, on_disk.robot.yaml_text)
    assert carried.yaml_path is None and carried.digest == on_disk.digest
    script = load_script(folder / "demo.yaml")
    assert _names_scene(script, carried)
    (folder / "scene.yaml").write_text(
        on_disk.yaml_text.replace("description:", "# x\ndescription:")
    )
    assert not _names_scene(script, carried)
