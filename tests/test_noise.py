"""Sensor models (smccli/world/noise.py): what each profile adds, seeded; scene files choose
them; perception still finds the objects through the realistic camera."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from smccli.errors import SceneError
from smccli.perception import clusters_from_frame
from smccli.perception.distance import d_cluster
from smccli.perception.params import scene_perception
from smccli.world.lidar import LidarReading
from smccli.world.noise import IDEAL, REALISTIC, NoisySensors, parse_noise
from smccli.world.scene import load_scene
from smccli.world.sensors import CameraFrame
from smccli.world.sim import Sim

REALISTIC_SCENE = (
    Path(__file__).parent.parent / "smccli" / "bench" / "scenes" / "bench_pick_realistic"
)


def _frame(depth: np.ndarray, rgb: np.ndarray | None = None) -> CameraFrame:
    h, w = depth.shape
    return CameraFrame(
        t=0.0,
        rgb=np.full((h, w, 3), 128, np.uint8) if rgb is None else rgb,
        depth=depth.astype(np.float32),
        K=np.array([[200.0, 0, w / 2], [0, 200.0, h / 2], [0, 0, 1]]),
        T_world_camera=np.eye(4),
    )


def test_ideal_changes_nothing() -> None:
    frame = _frame(np.full((40, 50), 1.0))
    s = NoisySensors(IDEAL, seed=3)
    assert s.frame(frame) is frame and s.weight(2.0, 0.123) == 0.123
    scan = LidarReading(0.0, np.array([1.0, np.inf]), -np.pi, np.pi, 8.0, np.zeros(3))
    assert s.scan(scan) is scan


def test_depth_noise_grows_with_distance_as_the_model_says() -> None:
    c = REALISTIC.camera
    for z in (0.6, 1.5):
        frame = _frame(np.full((200, 200), z))
        out = NoisySensors(REALISTIC, seed=1).frame(frame)
        err = out.depth[out.depth > 0] - z
        sigma = c.depth_a + c.depth_b * (z - c.depth_z0) ** 2
        assert np.std(err) == pytest.approx(sigma, rel=0.05)
        assert abs(np.mean(err)) < 0.1 * sigma
        # A flat wall has no edges and is not dark: only the random dropout.
        assert np.mean(out.depth == 0) == pytest.approx(c.dropout, abs=0.002)


def test_holes_at_edges_and_on_dark_surfaces() -> None:
    depth = np.full((100, 100), 1.0)
    depth[:, 50:] = 1.2  # a step: columns 49 and 50 are edge pixels
    rgb = np.full((100, 100, 3), 150, np.uint8)
    rgb[:50, :20] = 10  # a dark patch
    out = NoisySensors(REALISTIC, seed=2).frame(_frame(depth, rgb))
    holes = out.depth == 0
    c = REALISTIC.camera
    assert holes[:, 49:51].mean() == pytest.approx(c.edge_dropout, abs=0.1)
    assert holes[:50, :20].mean() == pytest.approx(c.dark_dropout, abs=0.06)
    assert holes[50:, 60:].mean() < 0.01


def test_colour_noise_and_exposure_are_seeded() -> None:
    frame = _frame(np.full((60, 60), 1.0))
    a, b = NoisySensors(REALISTIC, seed=5), NoisySensors(REALISTIC, seed=5)
    fa, fb = a.frame(frame), b.frame(frame)
    assert np.array_equal(fa.rgb, fb.rgb) and np.array_equal(fa.depth, fb.depth)
    c = REALISTIC.camera
    lo, hi = (1 - c.exposure) * (1 - c.white_balance), (1 + c.exposure) * (1 + c.white_balance)
    assert ((lo <= a.gain) & (a.gain <= hi)).all()
    mean = fa.rgb.reshape(-1, 3).mean(axis=0)
    np.testing.assert_allclose(mean, 128 * a.gain, atol=1.0)  # the gain, per channel
    spread = (fa.rgb.astype(float) - 128 * a.gain).reshape(-1, 3).std(axis=0)
    np.testing.assert_allclose(spread, 255 * c.colour_sigma, rtol=0.1)
    other = NoisySensors(REALISTIC, seed=6)
    assert not np.array_equal(other.frame(frame).rgb, fa.rgb)


def test_scale_noise_drift_and_lidar_dropouts() -> None:
    s = NoisySensors(REALISTIC, seed=7)
    n = REALISTIC.scale
    early = np.array([s.weight(0.0, 0.1) for _ in range(4000)])
    late = np.array([s.weight(600.0, 0.1) for _ in range(4000)])
    assert np.std(early) == pytest.approx(n.sigma, rel=0.1)
    assert abs(np.mean(early) - 0.1) <= n.offset + 1e-4
    assert np.mean(late) - np.mean(early) == pytest.approx(600.0 * s.scale_drift, abs=5e-5)
    ranges = np.full(20000, 2.0)
    scan = s.scan(LidarReading(0.0, ranges, -np.pi, 2 * np.pi / 20000, 8.0, np.zeros(3)))
    lost = ~np.isfinite(scan.ranges)
    assert lost.mean() == pytest.approx(REALISTIC.lidar.dropout, abs=0.003)
    sigma = REALISTIC.lidar.sigma + REALISTIC.lidar.sigma_rel * 2.0
    assert np.std(scan.ranges[~lost] - 2.0) == pytest.approx(sigma, rel=0.05)


def test_scene_files_choose_the_models_and_bad_values_are_one_line(tmp_path) -> None:
    assert load_scene("bench_pick").noise == IDEAL
    assert load_scene(REALISTIC_SCENE / "scene.yaml").noise == REALISTIC
    over = parse_noise({"profile": "realistic", "lidar": {"dropout": 0.05}}, "x")
    assert over.lidar.dropout == 0.05 and over.camera == REALISTIC.camera
    text = (
        (REALISTIC_SCENE / "scene.yaml")
        .read_text()
        .replace("mjcf: ../../../world", f"mjcf: {REALISTIC_SCENE.parents[2]}/world")
    )
    for bad, msg in (
        ("noise: noisy", "noise"),
        ("noise: {profile: realistic, camera: {exposur: 0.1}}", "exposur"),
        ("noise: {profile: realistic, scale: {sigma: -1}}", "sigma"),
    ):
        path = tmp_path / "scene.yaml"
        path.write_text(text.replace("noise: realistic", bad))
        with pytest.raises(SceneError, match=msg) as err:
            load_scene(path)
        assert "\n" not in str(err.value) and str(path) in str(err.value)


def test_perception_through_the_realistic_camera_still_matches_the_ideal_object() -> None:
    """The white box seen through the realistic camera (10 episodes' exposures and noise),
    with the scene's outlier filter: its cluster stays within T_hP = 0.1 of the ideal
    camera's, and its extents within 6 mm of the box's."""
    noisy_scene = load_scene(REALISTIC_SCENE / "scene.yaml")
    params = scene_perception(noisy_scene)
    ideal = Sim(load_scene("bench_pick"))
    truth = ideal.render_camera()
    ref = min(
        clusters_from_frame(truth, ideal.robot_geometry(), params), key=lambda c: c.extents[2]
    )
    sim = Sim(noisy_scene)
    for seed in range(10):
        sim.reset(noise_seed=seed)
        clusters = clusters_from_frame(sim.render_camera(), sim.robot_geometry(), params)
        box = min(clusters, key=lambda c: np.linalg.norm(c.centroid - ref.centroid))
        assert d_cluster(box, ref, params) < 0.1, seed
        np.testing.assert_allclose(np.sort(box.extents[:2]), [0.04, 0.14], atol=0.006)


def _frame_as_written(s: NoisySensors, frame: CameraFrame) -> CameraFrame:
    """The camera model as the module docstring states it, one full-frame array per step:
    the reference NoisySensors.frame must equal to the bit (draws in the same order)."""
    c, rng = s.noise.camera, s.rng
    depth = frame.depth.astype(np.float32, copy=True)
    valid = np.isfinite(depth) & (depth > 0)
    sigma = c.depth_a + c.depth_b * (depth - c.depth_z0) ** 2
    depth[valid] += (rng.standard_normal(int(valid.sum())) * sigma[valid]).astype(np.float32)
    rgb = frame.rgb.astype(np.float32) / 255.0
    luma = rgb @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
    jump = np.zeros(depth.shape, dtype=bool)
    with np.errstate(invalid="ignore"):  # inf - inf beside a hole: nan, not a jump
        dz_x = np.abs(np.diff(frame.depth, axis=1)) > c.edge_jump
        dz_y = np.abs(np.diff(frame.depth, axis=0)) > c.edge_jump
    jump[:, 1:] |= dz_x
    jump[:, :-1] |= dz_x
    jump[1:, :] |= dz_y
    jump[:-1, :] |= dz_y
    p = np.full(depth.shape, c.dropout, dtype=np.float32)
    p = np.maximum(p, np.where(jump, c.edge_dropout, 0.0))
    p = np.maximum(p, np.where(luma < c.dark_luma, c.dark_dropout, 0.0))
    depth[rng.random(depth.shape) < p] = 0.0
    depth[depth < 0] = 0.0
    rgb = rgb * s.gain.astype(np.float32)
    rgb += rng.standard_normal(rgb.shape).astype(np.float32) * c.colour_sigma
    out = np.clip(np.rint(rgb * 255.0), 0, 255).astype(np.uint8)
    return CameraFrame(frame.t, out, depth, frame.K, frame.T_world_camera)


@pytest.mark.parametrize("dropouts", [(0.5, 0.3, 0.002), (0.0, 0.7, 0.1), (0.9, 0.0, 0.0)])
def test_camera_model_is_the_full_frame_formula_to_the_bit(dropouts) -> None:
    """NoisySensors.frame (per-kind dropout lookup, in-place colour) gives the images of
    the model written one full-frame array per step, to the bit, and leaves the generator
    where it leaves it: edges, dark patches, holes (0, inf, nan), a depth near the camera."""
    rng = np.random.default_rng(5)
    depth = np.repeat(np.repeat(rng.uniform(0.3, 2.0, (12, 16)), 10, 0), 10, 1)
    depth += rng.normal(0, 0.002, depth.shape)
    depth[rng.random(depth.shape) < 0.02] = 0.0
    depth[:3, :4], depth[5, 7:12], depth[-1, -1] = np.inf, np.nan, 0.01
    rgb = np.repeat(np.repeat(rng.integers(0, 256, (12, 16, 3)), 10, 0), 10, 1).astype(np.uint8)
    frame = _frame(depth, rgb)
    edge, dark, anywhere = dropouts
    camera = replace(REALISTIC.camera, edge_dropout=edge, dark_dropout=dark, dropout=anywhere)
    for seed in range(3):
        a = NoisySensors(replace(REALISTIC, camera=camera), seed)
        b = NoisySensors(replace(REALISTIC, camera=camera), seed)
        for _ in range(2):
            got, want = a.frame(frame), _frame_as_written(b, frame)
            assert got.rgb.dtype == want.rgb.dtype and np.array_equal(got.rgb, want.rgb)
            assert got.depth.dtype == want.depth.dtype
            assert np.array_equal(got.depth, want.depth, equal_nan=True)
            assert np.array_equal(np.signbit(got.depth), np.signbit(want.depth))
        assert a.rng.random() == b.rng.random()


@pytest.mark.parametrize(
    "region",
    [(0, 120, 0, 160), (30, 95, 41, 118), (0, 7, 150, 160), (119, 120, 0, 1), (5, 5, 3, 9)],
)
def test_a_window_is_the_whole_noisy_frame_there_to_the_bit(region) -> None:
    """NoisySensors.frame with a window: its pixels are the full-frame formula's to the bit
    (its edges see their neighbours outside it), no reading elsewhere, and the generator
    is left where the whole frame leaves it; holes (0, inf, nan) outside the window too."""
    rng = np.random.default_rng(8)
    depth = np.repeat(np.repeat(rng.uniform(0.3, 2.0, (12, 16)), 10, 0), 10, 1)
    depth += rng.normal(0, 0.002, depth.shape)
    depth[rng.random(depth.shape) < 0.05] = 0.0
    depth[:3, :4], depth[5, 7:12], depth[40, 30:60] = np.inf, np.nan, np.inf
    rgb = np.repeat(np.repeat(rng.integers(0, 256, (12, 16, 3)), 10, 0), 10, 1).astype(np.uint8)
    frame = _frame(depth, rgb)
    v0, v1, u0, u1 = region
    inside = np.zeros(depth.shape, dtype=bool)
    inside[v0:v1, u0:u1] = True
    for seed in range(3):
        a, b = NoisySensors(REALISTIC, seed), NoisySensors(REALISTIC, seed)
        for _ in range(2):
            got, want = a.frame(frame, region), _frame_as_written(b, frame)
            assert got.rgb.dtype == want.rgb.dtype and got.depth.dtype == want.depth.dtype
            assert np.array_equal(got.rgb[inside], want.rgb[inside])
            assert np.array_equal(got.depth[inside], want.depth[inside], equal_nan=True)
            assert not got.depth[~inside].any() and not got.rgb[~inside].any()
        assert a.rng.random() == b.rng.random()
