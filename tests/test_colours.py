"""Colour names of rendered objects: each cube of a named colour is called by its name.

The cubes are rendered by the simulator's camera through the real perception pipeline;
their declared poses only pair each cluster with the cube it is (the assertion's side).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from smccli.perception import clusters_from_frame
from smccli.perception.colours import colour_name, dominant_hue, dominant_rgb
from smccli.perception.params import scene_perception
from smccli.world.layout import nominal_layout
from smccli.world.scene import load_scene
from smccli.world.sim import Sim

BENCH_XML = Path(__file__).resolve().parents[1] / "smccli/world/scenes/bench_pick/scene.xml"
COLOURS = {
    "red": (0.85, 0.08, 0.08),
    "orange": (1.0, 0.45, 0.05),  # bench_pick's orange box
    "yellow": (0.95, 0.85, 0.1),
    "green": (0.1, 0.7, 0.2),
    "cyan": (0.1, 0.75, 0.8),
    "blue": (0.1, 0.25, 0.85),
    "purple": (0.5, 0.15, 0.75),
    "pink": (0.95, 0.4, 0.7),
    "white": (0.95, 0.95, 0.95),
    "grey": (0.5, 0.5, 0.5),
    "black": (0.08, 0.08, 0.08),
}


def _scene(tmp_path: Path) -> Path:
    xs, ys = (0.38, 0.52, 0.66), (-0.3, -0.15, 0.0, 0.15)
    spots = [(x, y) for x in xs for y in ys]
    rows = []
    for (name, rgb), (x, y) in zip(COLOURS.items(), spots, strict=False):
        rows.append(
            f"  - {{name: {name}_cube, shape: box, size: [0.045, 0.045, 0.045], "
            f"rgba: [{rgb[0]}, {rgb[1]}, {rgb[2]}, 1], mass: 0.05, pose: [{x}, {y}, 0.0225, 0.3]}}"
        )
    path = tmp_path / "colours.yaml"
    path.write_text(
        f"name: colours\nmjcf: {BENCH_XML}\nrobot: arm\n"
        "sensors:\n  camera: {name: sensor_camera, width: 320, height: 240, rate: 10}\n"
        "objects:\n" + "\n".join(rows) + "\n"
        "success:\n  stacked:\n"
        "    all_of: [{object: red_cube, relation: on_top_of, target: blue_cube}]\n",
        encoding="utf-8",
    )
    return path


@pytest.fixture(scope="module")
def named_clusters(tmp_path_factory: pytest.TempPathFactory) -> list[tuple[str, str, float]]:
    scene = load_scene(_scene(tmp_path_factory.mktemp("colours")))
    sim = Sim(scene, nominal_layout(scene))
    try:
        params = scene_perception(scene)
        clusters = clusters_from_frame(sim.render_camera(), sim.robot_geometry(), params)
    finally:
        sim.close()
    p = params
    named = []
    for c in clusters:
        obj = min(scene.objects, key=lambda o: float(np.hypot(*(c.centroid[:2] - o.pose[:2]))))
        rgb = dominant_rgb(c.histogram, p.hue_bins, p.sat_bins, p.val_bins)
        hue = dominant_hue(c.histogram, p.hue_bins, p.sat_bins)
        named.append((obj.name.removesuffix("_cube"), colour_name(rgb), hue))
    return named


def test_every_rendered_cube_is_called_by_its_colour(named_clusters) -> None:
    assert sorted(n for n, _, _ in named_clusters) == sorted(COLOURS), named_clusters
    wrong = [(truth, said, round(h)) for truth, said, h in named_clusters if said != truth]
    assert not wrong, wrong


@pytest.mark.parametrize(
    ("rgb", "name"),
    [((255, 0, 0), "red"), ((255, 115, 13), "orange"), ((230, 20, 60), "red")],
)
def test_red_and_orange_are_apart(rgb: tuple[int, int, int], name: str) -> None:
    assert colour_name(rgb) == name
