"""Scenes: loading, text round trip, layouts, and the robot's reach over every layout."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest

from smccli.errors import SceneError, SmcError
from smccli.schemas import load_schema, parse_yaml, schema_problem, validate_yaml
from smccli.world.controller import reachable
from smccli.world.layout import load_layout_file, nominal_layout, sample_layout
from smccli.world.scene import (
    RELATIONS,
    ROBOT_KEY,
    SCENES_DIR,
    SHAPES,
    builtin_names,
    list_scenes,
    load_scene,
    load_scene_from_text,
)

SCENES = ["bench_pick", "bench_pick_panda", "pick_place", "rooms", "weigh_sort"]


def test_builtin_scenes_load() -> None:
    assert set(SCENES) <= set(builtin_names())
    for scene in list_scenes():
        model = scene.model()
        assert scene.digest.startswith("sha256:") and len(scene.digest) == 71
        assert model.opt.cone == 1 and model.opt.impratio >= 10  # elliptic cones
        assert abs(model.opt.timestep - 0.002) < 1e-9
        for obj in scene.objects:
            assert obj.range_x[0] <= obj.pose[0] <= obj.range_x[1], obj.name


def test_load_by_path_equals_by_name() -> None:
    a = load_scene("pick_place")
    b = load_scene(SCENES_DIR / "pick_place" / "scene.yaml")
    assert a.digest == b.digest and a.yaml_path == b.yaml_path


def test_unknown_scene_lists_valid_names() -> None:
    with pytest.raises(SceneError, match="nowhere.*pick_place"):
        load_scene("nowhere")


def test_bad_scene_file_names_the_file(tmp_path) -> None:
    bad = tmp_path / "scene.yaml"
    bad.write_text(
        "name: x\nobjects:\n  - {name: a, shape: sphere, size: [1, 1, 1], pose: [0, 0, 0, 0]}\n"
    )
    (tmp_path / "scene.xml").write_text("<mujoco/>")
    with pytest.raises(SceneError, match=r"scene.yaml.*sphere.*box"):
        load_scene(bad)


def test_rebuild_from_embedded_text() -> None:
    scene = load_scene("weigh_sort")
    again = load_scene_from_text(scene.yaml_text, scene.mjcf)
    assert again.digest == scene.digest
    assert again.objects == scene.objects and again.scale == "scale"
    assert again.model().nq == scene.model().nq


def test_sample_layout_in_ranges_without_overlap() -> None:
    for scene in list_scenes():
        rng = np.random.default_rng(0)
        for _ in range(50):
            layout = sample_layout(scene, rng)
            variants = [set(names) for _, names in scene.variants]
            optional = set().union(*variants) if variants else set()
            present = set(layout) & optional
            assert not variants or present in variants  # exactly one variant's objects
            for f in scene.furniture:  # moved as a whole, within its ranges
                x, y, _, yaw = layout[f.name]
                assert f.range_x[0] <= x <= f.range_x[1] and f.range_y[0] <= y <= f.range_y[1]
                assert f.range_yaw[0] <= yaw <= f.range_yaw[1]
            for o in scene.objects:
                # On furniture, the ranges hold in its nominal frame (test_loco_manip.py).
                if o.name not in layout or o.on is not None:
                    continue
                x, y, _, yaw = layout[o.name]
                assert o.range_x[0] <= x <= o.range_x[1]
                assert o.range_y[0] <= y <= o.range_y[1]
                assert o.range_yaw[0] <= yaw <= o.range_yaw[1]
            if scene.start is not None:  # a mobile base's start, within its ranges
                x, y, _, yaw = layout[ROBOT_KEY]
                st = scene.start
                assert st.range_x[0] <= x <= st.range_x[1]
                assert st.range_y[0] <= y <= st.range_y[1]
                assert st.range_yaw[0] <= yaw <= st.range_yaw[1]
            furniture = {f.name for f in scene.furniture}
            names = [n for n in layout if n != ROBOT_KEY and n not in furniture]
            for i, a in enumerate(names):
                for b in names[i + 1 :]:
                    d = math.dist(layout[a][:2], layout[b][:2])
                    ra, rb = scene.object(a).footprint_radius, scene.object(b).footprint_radius
                    assert d >= ra + rb
        assert sample_layout(scene, np.random.default_rng(3)) == sample_layout(
            scene, np.random.default_rng(3)
        )
        robot = {ROBOT_KEY} if scene.start is not None else set()
        furniture = {f.name for f in scene.furniture}
        assert set(nominal_layout(scene)) == {o.name for o in scene.objects} | robot | furniture
        for variant, names in scene.variants:
            assert set(names) <= set(nominal_layout(scene, variant))


def test_bench_pick_ranges_as_in_the_paper() -> None:
    box = load_scene("bench_pick").object("white_box")
    assert box.range_y[1] - box.range_y[0] >= 0.5  # along the table
    assert box.range_x[1] - box.range_x[0] >= 0.25  # across
    assert box.range_yaw[1] - box.range_yaw[0] >= 2 * math.pi - 1e-3


@pytest.mark.parametrize("name", SCENES)
def test_robot_reaches_every_layout_at_any_yaw(name: str) -> None:
    """Grasp height and 15 cm above, at range corners and centre, at 8 yaws over a turn."""
    scene = load_scene(name)
    model = scene.model()
    for o in scene.objects:
        if o.fixed:
            continue
        xs, ys = o.range_x, o.range_y
        points = [(x, y) for x in xs for y in ys] + [(sum(xs) / 2, sum(ys) / 2)]
        grasp_z = max(o.size[2] / 2, 0.02)
        for x, y in points:
            for z in (grasp_z, grasp_z + 0.15):
                for yaw in np.linspace(-math.pi, math.pi, 8, endpoint=False):
                    assert reachable(model, scene.robot, np.array([x, y, z, yaw])), (
                        o.name,
                        x,
                        y,
                        z,
                        yaw,
                    )


# --- the scene file's schema ---------------------------------------------------------------


def fields_without_description(schema: Any, root: dict, at: str = "") -> list[str]:
    """Property schemas without a description (theirs or their ``$ref``'s), and mappings with
    named keys that accept unknown ones."""
    out: list[str] = []
    if isinstance(schema, dict):
        props = schema.get("properties")
        if props is not None:
            if schema.get("additionalProperties") is not False:
                out.append(f"{at}: additionalProperties is not false")
            for key, sub in props.items():
                ref = sub.get("$ref", "#/")[2:]
                target = root
                for part in filter(None, ref.split("/")):
                    target = target[part]
                if "description" not in sub and "description" not in target:
                    out.append(f"{at}.{key}: no description")
        for key, sub in schema.items():
            if key != "enum":
                out += fields_without_description(sub, root, f"{at}/{key}")
    elif isinstance(schema, list):
        for i, sub in enumerate(schema):
            out += fields_without_description(sub, root, f"{at}[{i}]")
    return out


@pytest.mark.parametrize("name", ["scene", "layout"])
def test_schema_is_valid_and_describes_every_field(name: str) -> None:
    schema = load_schema(name)
    jsonschema.Draft202012Validator.check_schema(schema)
    assert fields_without_description(schema, schema) == []


def test_scene_schema_enums_are_the_codes() -> None:
    defs = load_schema("scene")["$defs"]
    assert tuple(defs["object"]["properties"]["shape"]["enum"]) == SHAPES
    assert tuple(defs["object_condition"]["properties"]["relation"]["enum"]) == RELATIONS


@pytest.mark.parametrize("name", SCENES)
def test_builtin_scene_files_fit_the_schema(name: str) -> None:
    path = SCENES_DIR / name / "scene.yaml"
    assert schema_problem(parse_yaml(path.read_text(), str(path), SceneError), "scene") is None


@pytest.fixture
def user_scene(tmp_path: Path) -> Path:
    """A copy of pick_place as a user's scene (its robot: the built-in arm, by name)."""
    shutil.copytree(SCENES_DIR / "pick_place", tmp_path / "mine")
    return tmp_path / "mine" / "scene.yaml"


def break_scene(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert text.count(old) >= 1, old
    path.write_text(text.replace(old, new, 1))


def line_of(path: Path, needle: str) -> int:
    """Line (1-based) of the first line holding ``needle``."""
    lines = path.read_text().splitlines()
    return next(i + 1 for i, ln in enumerate(lines) if needle in ln)


# (old text, new text, key path, line holding, what the message says)
BROKEN_SCENES = {
    "wrong type": (
        "mass: 0.3",
        "mass: heavy",
        "objects[2].mass",
        "mass: heavy",
        "expected a number, found 'heavy'",
    ),
    "unknown key": (
        "    rgba: [0.5, 0.5, 0.5, 1]",
        "    colour: [0.5, 0.5, 0.5, 1]",
        "objects[1].colour",
        "colour:",
        "unknown key 'colour' (valid: name, shape, size, rgba, mass, pose, range, fixed, "
        "rests_on, wall)",
    ),
    "missing key": (
        "    pose: [0.58, -0.08, 0.03, -0.4]\n",
        "",
        "objects[1]",
        "name: grey_pyramid",
        "missing required key 'pose'",
    ),
    "bad enum": (
        "shape: pyramid",
        "shape: sphere",
        "objects[1].shape",
        "shape: sphere",
        "unknown value 'sphere' (valid: box, cylinder, pyramid, open_box, scale, mug)",
    ),
}


@pytest.mark.parametrize("case", sorted(BROKEN_SCENES))
def test_broken_scene_file_names_key_path_and_line(user_scene: Path, case: str) -> None:
    old, new, path, holder, what = BROKEN_SCENES[case]
    break_scene(user_scene, old, new)
    line = line_of(user_scene, holder)
    with pytest.raises(SceneError) as info:
        load_scene(user_scene)
    assert str(info.value) == f"{user_scene}: {path} (line {line}): {what}"


@pytest.mark.parametrize(
    "old, new, expected",
    [
        (
            "relation: on_top_of",
            "relation: under",
            "success.cube_on_green.any_of[0].relation (line 45): "
            "unknown value 'under' (valid: on_top_of, inside)",
        ),
        (
            "y: [-0.35, -0.05]",
            "y: [-0.35, abc]",
            "objects[0].range.y[1] (line 17): expected a number, found 'abc'",
        ),
        (
            "size: [0.05, 0.05, 0.05]",
            "size: [0.05, 0.05]",
            "objects[0].size (line 13): expected 3 items, found 2",
        ),
        (
            "size: [0.05, 0.05, 0.05]",
            "size: [0.05, 0, 0.05]",
            "objects[0].size[1] (line 13): expected a number > 0, found 0",
        ),
        ("width: 320", "width: 320.5", "sensors.camera.width (line 9): expected an integer"),
        (
            "description:",
            "descrption:",
            "descrption (line 5): unknown key 'descrption' (valid: name, description",
        ),
        ("objects:", "objs:", "top level (line 4): missing required key 'objects'"),
        (
            "  - name: grey_pyramid",
            "  - grey_pyramid\n  - name: grey_pyramid",
            "objects[1] (line 18): expected a mapping, found 'grey_pyramid'",
        ),
        (
            "cube_green: [orange_cube, green_cylinder]",
            "cube_green: []",
            "variants.cube_green (line 41): expected at least 1 item, found 0",
        ),
        ("name: pick_place", "name: [\n", "not valid YAML: "),
        (
            "pose: [0.42, 0.2, 0.04, 0.0]",
            "pose: [0.42, .inf, 0.04, 0.0]",
            "objects[2].pose[1] (line 30): expected a finite number, found inf",
        ),
        # Checks the schema cannot make, still with the key path and line.
        (
            "cube_green: [orange_cube, green_cylinder]",
            "cube_green: [orange_cube, blue_cylinder]",
            "variants.cube_green[1] (line 41): no object 'blue_cylinder' (objects: orange_cube, ",
        ),
        (
            "target: yellow_cylinder}",
            "target: yellow}",
            "success.pyramid_on_yellow.any_of[0].target (line 47): no object 'yellow'",
        ),
        (
            "x: [0.33, 0.6], y: [-0.35",
            "x: [0.6, 0.33], y: [-0.35",
            "objects[0].range.x (line 17): expected [low, high], found low 0.6 above high 0.33",
        ),
        (
            "name: grey_pyramid",
            "name: orange_cube",
            "objects[1].name (line 18): duplicate object name 'orange_cube'",
        ),
        (
            "sensors:\n",
            "sensors:\n  scale: green_cylinder\n",
            "sensors.scale (line 9): no object 'green_cylinder' of shape scale (scales: none)",
        ),
        (
            "robot: arm ",
            "robot: arms ",
            "robot (line 7): no robot 'arms' (built-in robots: arm, base, mobile_panda, panda",
        ),
    ],
    ids=lambda v: v if len(v) < 30 else None,
)
def test_scene_file_problems(user_scene: Path, old: str, new: str, expected: str) -> None:
    break_scene(user_scene, old, new)
    with pytest.raises(SceneError) as info:
        load_scene(user_scene)
    msg = str(info.value)
    assert msg.startswith(f"{user_scene}: ") and "\n" not in msg
    assert expected in msg, msg


def test_user_scene_by_path_loads(user_scene: Path) -> None:
    scene = load_scene(user_scene)
    assert scene.name == "pick_place" and scene.yaml_path == user_scene
    assert scene.objects == load_scene("pick_place").objects


def test_validate_yaml_serves_any_schema(tmp_path: Path) -> None:
    """The helper is generic: a schema name, a source and the error class to raise."""

    class RobotError(SmcError):
        pass

    data = validate_yaml("a: [1, 2, 3]\n", "layout", "robot.yaml", RobotError)
    assert data == {"a": [1, 2, 3]}
    with pytest.raises(
        RobotError, match=r"^robot\.yaml: b \(line 2\): expected a list, found 'x'$"
    ):
        validate_yaml("a: [1, 2, 3]\nb: x\n", "layout", "robot.yaml", RobotError)
    with pytest.raises(RobotError, match=r"^robot\.yaml: not valid YAML"):
        validate_yaml("a: [1, 2\n", "layout", "robot.yaml", RobotError)
    with pytest.raises(RobotError, match="not valid YAML"):  # no arbitrary Python objects
        validate_yaml("a: !!python/object/apply:os.system [echo]\n", "layout", "r.yaml", RobotError)


# --- layout files (smc replay --layout) -------------------------------------------------------


def test_layout_file_reads_poses(tmp_path: Path) -> None:
    scene = load_scene("pick_place")
    path = tmp_path / "layout.yaml"
    path.write_text("orange_cube: [0.4, -0.2, 0.025, 0.3]\ngreen_cylinder: [0.45, 0.2, 1.0]\n")
    layout = load_layout_file(path, scene)
    assert layout == {
        "orange_cube": (0.4, -0.2, 0.025, 0.3),
        "green_cylinder": (0.45, 0.2, scene.object("green_cylinder").pose[2], 1.0),
    }
    as_json = tmp_path / "layout.json"
    as_json.write_text(json.dumps({k: list(v) for k, v in layout.items()}))
    assert load_layout_file(as_json, scene) == layout


@pytest.mark.parametrize(
    "text, expected",
    [
        ("orange_cube: [0.4, -0.2]\n", "orange_cube (line 1): expected 3 to 4 items, found 2"),
        (
            "orange_cube: [0.4, -0.2, 0, 0]\nblue_whale: [0, 0, 0]\n",
            "blue_whale (line 2): no object 'blue_whale' in scene pick_place (objects: orange_cube",
        ),
        (
            "orange_cube: [0.4, x, 0.1]\n",
            "orange_cube[1] (line 1): expected a number, found 'x'",
        ),
        ("- [0.4, 0.1, 0.1]\n", "top level (line 1): expected a mapping, found [[0.4"),
        ("{}\n", "top level (line 1): expected at least 1 entries, found 0"),
        ("orange_cube: [0.4,\n", "not valid YAML"),
    ],
)
def test_bad_layout_file_names_key_and_line(tmp_path: Path, text: str, expected: str) -> None:
    path = tmp_path / "layout.yaml"
    path.write_text(text)
    with pytest.raises(SceneError) as info:
        load_layout_file(path, load_scene("pick_place"))
    msg = str(info.value)
    assert msg.startswith(f"{path}: ") and expected in msg, msg
    with pytest.raises(SceneError, match="nothere.yaml: cannot read layout"):
        load_layout_file(tmp_path / "nothere.yaml", load_scene("pick_place"))


# --- through the real command ---------------------------------------------------------------


@pytest.mark.parametrize("case", sorted(BROKEN_SCENES))
def test_record_with_broken_scene_exits_2_with_one_line(
    user_scene: Path, tmp_path: Path, case: str
) -> None:
    old, new, path, holder, what = BROKEN_SCENES[case]
    break_scene(user_scene, old, new)
    line = line_of(user_scene, holder)
    out = tmp_path / "out.mcap"
    script = Path(__file__).resolve().parents[1] / "sample_logs" / "pick_place" / "demo1.yaml"
    proc = subprocess.run(
        [sys.executable, "-m", "smccli.cli", "record", "--scene", str(user_scene)]
        + ["--script", str(script), "-o", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "COLUMNS": "400"},
    )
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    assert f"{user_scene}: {path} (line {line}): {what}" in lines[0]
    assert "Traceback" not in proc.stderr
    assert not out.exists() and not out.with_name("out.mcap.part").exists()


def test_a_geom_in_the_sensors_hidden_group_is_refused(user_scene: Path) -> None:
    """Group 5 is smc's: no sensor sees it (parked objects, the teleop marker). A scene
    geom put there would be invisible to the robot without a word: refused in one line."""
    xml = user_scene.parent / "scene.xml"
    break_scene(xml, '<geom name="floor"', '<geom name="floor" group="5"')
    with pytest.raises(SceneError) as info:
        load_scene(user_scene)
    msg = str(info.value)
    assert "\n" not in msg and "geom floor in group 5, which no sensor sees" in msg, msg


def test_each_model_is_fresh_but_a_scene_compiles_once_per_process(monkeypatch):
    """Scene.model() gives a model of its own each call (a layout may rewrite it), copied
    from the one compiled the first time: the same numbers, no second compile."""
    import mujoco

    scene = load_scene("pick_place")
    first = scene.model()
    compiles = []
    compile_xml = mujoco.MjModel.from_xml_string

    def counted(*args, **kwargs):
        compiles.append(1)
        return compile_xml(*args, **kwargs)

    monkeypatch.setattr(mujoco.MjModel, "from_xml_string", counted)
    second = scene.model()
    assert compiles == [] and second is not first
    for name in ("body_pos", "geom_size", "geom_rgba", "jnt_range", "mesh_vert"):
        np.testing.assert_array_equal(getattr(first, name), getattr(second, name))
    second.body_pos[1, 0] += 1.0  # its own copy
    assert first.body_pos[1, 0] != second.body_pos[1, 0]
    assert scene.model().body_pos[1, 0] == first.body_pos[1, 0]
