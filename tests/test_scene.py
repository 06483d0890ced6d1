"""Scenes: loading, text round trip, layouts, and the robot's reach over every layout."""

from __future__ import annotations

import math

import numpy as np
import pytest

from smccli.controller import reachable
from smccli.errors import SceneError
from smccli.scene import (
    SCENES_DIR,
    builtin_names,
    list_scenes,
    load_scene,
    load_scene_from_text,
    nominal_layout,
    sample_layout,
)

SCENES = ["bench_pick", "pick_place", "weigh_sort"]


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
            for o in scene.objects:
                if o.name not in layout:
                    continue
                x, y, _, yaw = layout[o.name]
                assert o.range_x[0] <= x <= o.range_x[1]
                assert o.range_y[0] <= y <= o.range_y[1]
                assert o.range_yaw[0] <= yaw <= o.range_yaw[1]
            names = list(layout)
            for i, a in enumerate(names):
                for b in names[i + 1 :]:
                    d = math.dist(layout[a][:2], layout[b][:2])
                    ra, rb = scene.object(a).footprint_radius, scene.object(b).footprint_radius
                    assert d >= ra + rb
        assert sample_layout(scene, np.random.default_rng(3)) == sample_layout(
            scene, np.random.default_rng(3)
        )
        assert set(nominal_layout(scene)) == {o.name for o in scene.objects}
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
                    assert reachable(model, np.array([x, y, z, yaw])), (o.name, x, y, z, yaw)
