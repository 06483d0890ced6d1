"""Sim: stepping, sensors (camera depth, scale), robot geometry; its truth (ground truth,
success) through :class:`smccli.world.truth.Truth`."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from smccli.world.layout import nominal_layout
from smccli.world.scene import load_scene
from smccli.world.sensors import CameraFrame, DrawingFrame, PoiCommand
from smccli.world.sim import HIDDEN_GROUP, Sim
from smccli.world.truth import Truth


@pytest.fixture(scope="module")
def pick_sim() -> Sim:
    return Sim(load_scene("pick_place"))


def test_step_advances_one_control_period(pick_sim: Sim) -> None:
    sim = Sim(load_scene("pick_place"))
    poi = sim.poi()
    assert poi.shape == (4,) and sim.gripper_opening() == pytest.approx(1.0)
    sim.step(PoiCommand(sim.t, poi, 1.0))
    assert sim.t == pytest.approx(0.01)
    js = sim.joint_state()
    assert js.names[:7] == tuple(f"joint{i}" for i in range(1, 8))
    assert js.position.shape == js.velocity.shape == js.effort.shape == (9,)
    assert sim.weight() is None  # no scale in this scene


def test_gripper_closes_and_opens() -> None:
    sim = Sim(load_scene("pick_place"))
    target = sim.poi()
    for _ in range(100):
        sim.step(PoiCommand(sim.t, target, 0.0))
    assert sim.gripper_opening() < 0.02
    for _ in range(100):
        sim.step(PoiCommand(sim.t, target, 0.5))
    assert sim.gripper_opening() == pytest.approx(0.5, abs=0.02)


@pytest.mark.parametrize("name, mass", [("light_box", 0.1), ("heavy_box", 0.5)])
def test_scale_reads_known_mass_within_2_g(name: str, mass: float) -> None:
    scene = load_scene("weigh_sort")
    layout = nominal_layout(scene)
    sx, sy, sz, _ = layout["scale"]
    top = sz + scene.object("scale").size[2] / 2
    layout[name] = (sx, sy, top + 0.026, 0.3)
    sim = Sim(scene, layout)
    assert sim.weight() == pytest.approx(0.0, abs=1e-6)  # tared
    sim.settle(1.0)
    assert sim.weight() == pytest.approx(mass, abs=0.002)


def test_depth_of_an_object_is_where_it_is(pick_sim: Sim) -> None:
    frame = pick_sim.render_camera()
    h, w = pick_sim.scene.camera.height, pick_sim.scene.camera.width
    assert frame.rgb.shape == (h, w, 3) and frame.rgb.dtype == np.uint8
    assert frame.depth.shape == (h, w) and frame.depth.dtype == np.float32
    T_camera_world = np.linalg.inv(frame.T_world_camera)
    for name, (r, g, b) in [("orange_cube", (255, 115, 13)), ("green_cylinder", (26, 178, 51))]:
        pose = Truth(pick_sim).ground_truth()[name]
        top = pose[:3] + [0, 0, pick_sim.scene.object(name).size[2] / 2]
        p = T_camera_world @ np.append(top, 1.0)
        u, v, _ = frame.K @ (p[:3] / p[2])
        ui, vi = round(u), round(v)
        # The top face is seen from above: its centre pixel's depth is that point's z.
        assert frame.depth[vi, ui] == pytest.approx(p[2], abs=0.004), name
        px = frame.rgb[vi, ui].astype(int)
        assert np.argmax(px) == np.argmax([r, g, b]), (name, px)
    # Back-project the depth image: the table is at z = 0 in the world.
    vs, us = np.mgrid[200:220, 150:170]
    z = frame.depth[vs, us]
    rays = np.linalg.inv(frame.K) @ np.stack([us.ravel(), vs.ravel(), np.ones(us.size)])
    pts = frame.T_world_camera[:3, :3] @ (rays * z.ravel()) + frame.T_world_camera[:3, 3:4]
    np.testing.assert_allclose(pts[2], 0.0, atol=0.003)


def test_every_layout_position_is_in_view() -> None:
    for name in ("pick_place", "weigh_sort", "bench_pick"):
        sim = Sim(load_scene(name))
        cam = sim.scene.camera
        T_camera_world = np.linalg.inv(sim.camera_pose())
        for o in sim.scene.objects:
            r = o.footprint_radius
            for x in (o.range_x[0] - r, o.range_x[1] + r):
                for y in (o.range_y[0] - r, o.range_y[1] + r):
                    p = T_camera_world @ [x, y, 0.0, 1.0]
                    u, v, _ = sim.camera_matrix() @ (p[:3] / p[2])
                    assert 0 <= u < cam.width and 0 <= v < cam.height, (name, o.name, x, y)


def test_robot_geometry_covers_the_hand(pick_sim: Sim) -> None:
    geom = pick_sim.robot_geometry()
    assert geom.centers.shape == (len(geom.radii), 3) and len(geom.radii) > 10
    d = pick_sim.data
    for name in ("finger_left_geom", "finger_right_geom", "link4_geom"):
        g = pick_sim.model.geom(name).id
        for corner in (-1, 1):  # both ends of the geom's long axis
            p = d.geom_xpos[g] + corner * d.geom_xmat[g].reshape(3, 3)[:, 2] * 0.04
            assert (np.linalg.norm(geom.centers - p, axis=1) <= geom.radii + 1e-9).any(), name
    # The space between the open fingers (where a grasped object is) stays free.
    assert not (np.linalg.norm(geom.centers - pick_sim.poi()[:3], axis=1) < geom.radii).any()
    base = np.linalg.norm(geom.centers - [0, 0, 0.06], axis=1) < geom.radii
    assert base.any()


def test_ground_truth_and_success(pick_sim: Sim) -> None:
    gt = Truth(pick_sim).ground_truth()
    assert set(gt) == {o.name for o in pick_sim.scene.objects}
    for pose in gt.values():
        assert pose.shape == (7,) and np.linalg.norm(pose[3:]) == pytest.approx(1.0)
    result = Truth(pick_sim).success()
    assert not result and "not resting on" in result.reason


def test_success_when_placed_by_hand() -> None:
    scene = load_scene("pick_place")
    layout = nominal_layout(scene)
    gx, gy, gz, _ = layout["green_cylinder"]
    layout["orange_cube"] = (gx + 0.01, gy, gz + 0.04 + 0.026, 0.0)
    sim = Sim(scene, layout)
    sim.settle(1.0)
    assert Truth(sim).success() and Truth(sim).success("cube_on_green")
    assert not Truth(sim).success("pyramid_on_yellow")


def _placed(scene_name: str, name: str, pose: tuple, variant: str | None = None) -> Truth:
    scene = load_scene(scene_name)
    layout = nominal_layout(scene, variant)
    layout[name] = pose
    sim = Sim(scene, layout)
    sim.settle(2.0)
    return Truth(sim)


def test_success_is_strict_about_the_footprint_rest_and_support() -> None:
    """Strict success: a box leaning over the container's wall, its centre inside,
    fails; so does one still moving; a cube
    that slid off the cylinder onto the table fails and says what it touches."""
    ox, oy, _, _ = load_scene("bench_pick").object("orange_box").pose
    inside = _placed("bench_pick", "white_box", (ox, oy, 0.031, 0.0))
    assert inside.success() and inside.success().reason == "box_in_box: white_box inside orange_box"
    leaning = _placed("bench_pick", "white_box", (ox, oy + 0.04, 0.1, np.pi / 2))
    centre = leaning.object_pose("white_box")[:2] - [ox, oy]
    assert abs(centre[1]) < 0.08 - 0.01 - 0.02  # the centre is well inside the inner walls
    assert not leaning.success() and "not resting inside" in leaning.success().reason
    moving = _placed("bench_pick", "white_box", (ox, oy, 0.031, 0.0))
    moving.data.qvel[moving.sim.free_joints["white_box"][1] + 5] = 1.0  # spinning about z
    assert not moving.success() and "moving" in moving.success().reason
    g = load_scene("pick_place").object("green_cylinder").pose
    off = _placed("pick_place", "orange_cube", (g[0] + 0.045, g[1], 0.106, 0.3), "cube_green")
    assert not off.success() and "touching table" in off.success().reason


def test_the_teleop_marker_changes_neither_physics_nor_camera() -> None:
    """The keyboard viewer's target marker (a mocap body, geom group 5): the same commands
    give the same states to the bit, and the sensor camera renders the same pixels."""
    scene = load_scene("pick_place")
    plain, marked = Sim(scene), Sim(scene, target_marker=True)
    assert marked.marker_id >= 0 and plain.marker_id == -1
    mocap = marked.model.body_mocapid[marked.marker_id]
    marked.data.mocap_pos[mocap] = marked.poi()[:3]  # where the viewer shows it
    target = plain.poi()
    for k in range(200):
        cmd = PoiCommand(plain.t, target + [0.0005 * k, 0.0003 * k, -0.0002 * k, 0.0], 1.0)
        plain.step(cmd)
        marked.step(cmd)
    assert np.array_equal(plain.data.qpos, marked.data.qpos)
    a, b = plain.render_camera(), marked.render_camera()
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth)


def test_reset_puts_back_what_a_layout_moved_in_the_model() -> None:
    """A layout moves furniture and fixed objects in the model itself (static bodies):
    a reset for a layout that leaves the wardrobe out is the simulator built for it, the
    wardrobe back at its scene pose (campaign workers reset one simulator per trial)."""
    scene = load_scene("loco_manip")
    moved = nominal_layout(scene)
    x, y, z, yaw = moved["wardrobe"]
    moved["wardrobe"] = [x + 0.05, y - 0.05, z, yaw + 0.08]
    without = {k: v for k, v in nominal_layout(scene).items() if k != "wardrobe"}
    sim, fresh = Sim(scene, moved), Sim(scene, without)
    assert not np.array_equal(sim.model.body_pos, fresh.model.body_pos)
    sim.reset(without)
    np.testing.assert_array_equal(sim.model.body_pos, fresh.model.body_pos)
    np.testing.assert_array_equal(sim.model.body_quat, fresh.model.body_quat)
    np.testing.assert_array_equal(sim.data.qpos, fresh.data.qpos)
    np.testing.assert_array_equal(sim.render_camera().depth, fresh.render_camera().depth)
    sim.close()
    fresh.close()


def _variant_layouts():
    """Every built-in scene at the nominal layout of each of its variants (the other
    variants' objects parked), or of all its objects."""
    from smccli.world.scene import builtin_names

    for name in builtin_names():
        scene = load_scene(name)
        for variant in [v for v, _ in scene.variants] or [None]:
            yield pytest.param(name, variant, id=f"{name}-{variant or 'all'}")


@pytest.mark.parametrize("name, variant", list(_variant_layouts()))
def test_no_object_moves_while_the_robot_stands_still(name: str, variant: str | None) -> None:
    """With the robot holding its home posture for 3 s, no free object moves faster than
    0.5 m/s, present or parked (loco_manip's parked object, under its floor plane, was
    thrown out at 22 m/s). Parked objects sit under every geom of the scene, touch nothing,
    and no sensor's geom group shows them."""
    scene = load_scene(name)
    sim = Sim(scene, nominal_layout(scene, variant))
    m, d = sim.model, sim.data
    free = {o.name: m.body(o.name).id for o in scene.objects if not o.fixed}
    parked = [o.name for o in scene.objects if o.name not in sim.present]
    top_speed = dict.fromkeys(free, 0.0)
    for _ in range(300):
        sim.step(PoiCommand(sim.t, sim.poi(), 1.0))
        for n, b in free.items():
            v = np.zeros(6)
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, b, v, 0)
            top_speed[n] = max(top_speed[n], float(np.linalg.norm(v[3:])))
    assert max(top_speed.values(), default=0.0) < 0.5, top_speed
    lowest = min(
        float(d.geom_xpos[g, 2] - m.geom_rbound[g])
        for g in range(m.ngeom)
        if m.body_rootid[m.geom_bodyid[g]] not in {m.body(n).id for n in parked}
    )
    for n in parked:
        b = m.body(n).id
        geoms = np.flatnonzero(m.geom_bodyid == b)
        assert d.xpos[b][2] == pytest.approx(sim.park_z, abs=1e-3) and d.xpos[b][2] < lowest
        assert (m.geom_contype[geoms] == 0).all() and (m.geom_conaffinity[geoms] == 0).all()
        assert (m.geom_group[geoms] == HIDDEN_GROUP).all()
        touching = {int(d.contact[i].geom1) for i in range(d.ncon)} | {
            int(d.contact[i].geom2) for i in range(d.ncon)
        }
        assert not touching & set(geoms.tolist())
    # A reset to a layout that shows them puts them back in the world.
    sim.reset(nominal_layout(scene, None) if scene.variants else None)
    assert (m.geom_group == sim._geom_group0).all() and (m.geom_contype == sim._geom_contype0).all()


@pytest.mark.parametrize("region", [(60, 150, 100, 220), (0, 37, 291, 320), (10, 10, 5, 50)])
def test_a_region_of_the_camera_is_the_frame_there_and_no_reading_elsewhere(pick_sim, region):
    """A look renders only a window of the image: its colours are the whole frame's, its
    depths within a micrometre of them (another projection matrix), and outside it there
    is no reading."""
    whole = pick_sim.render_camera()
    part = pick_sim.render_camera(region)
    v0, v1, u0, u1 = region
    inside = np.zeros(whole.depth.shape, dtype=bool)
    inside[v0:v1, u0:u1] = True
    assert np.array_equal(part.rgb[inside], whole.rgb[inside])
    assert np.abs(part.depth[inside] - whole.depth[inside]).max(initial=0.0) < 1e-5
    assert not part.depth[~inside].any() and not part.rgb[~inside].any()
    assert np.array_equal(part.K, whole.K) and np.array_equal(
        part.T_world_camera, whole.T_world_camera
    )


def test_a_noisy_region_is_the_whole_noisy_frame_there_to_the_bit() -> None:
    """A camera with noise: a look's window is the whole noisy frame's there, to the bit
    but for a rare colour on an edge (the window's lit pass has its own projection), no
    reading elsewhere, and the next frame is the same (the same draws)."""
    scene = load_scene(
        Path(__file__).parent.parent / "smccli/bench/scenes/bench_pick_realistic/scene.yaml"
    )
    sim = Sim(scene)
    v0, v1, u0, u1 = region = (60, 150, 100, 220)
    frames = []
    for look in (None, region):
        sim.reset(noise_seed=11)
        frames.append((sim.render_camera(look), sim.render_camera()))
    (whole, after), (part, after_part) = frames
    inside = np.zeros(whole.depth.shape, dtype=bool)
    inside[v0:v1, u0:u1] = True
    assert np.count_nonzero((part.rgb != whole.rgb).any(axis=2)[inside]) <= 2
    assert np.array_equal(part.depth[inside], whole.depth[inside])
    assert (part.depth[inside] == 0).any()  # holes: the noise is there
    assert not part.depth[~inside].any() and not part.rgb[~inside].any()
    assert np.array_equal(after_part.rgb, after.rgb)
    assert np.array_equal(after_part.depth, after.depth)


def test_a_frame_read_late_holds_the_instant_it_was_drawn_to_the_bit() -> None:
    """A decision's frame has its colours drawn after its depth and read at their first
    use (DrawingFrame): read after the world moved and the camera drew again (a whole frame
    and a window), they are still the instant's, to the bit of mujoco.Renderer's lit
    pass then."""
    sim = Sim(load_scene("pick_place"))
    renderer = mujoco.Renderer(sim.model, sim.scene.camera.height, sim.scene.camera.width)
    renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
    renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
    option = sim._camera._option()
    early, expected = [], []
    for _ in range(3):
        renderer.update_scene(sim.data, camera=sim._camera.cam_id, scene_option=option)
        expected.append(renderer.render().copy())
        early.append(sim.render_camera(colour_later=True))
        for _ in range(40):  # the arm moves into view and out of its home pose
            sim.step(PoiCommand(sim.t, sim.poi() + [0.004, -0.003, -0.004, 0.01], 0.2))
    sim.render_camera((60, 150, 100, 220))
    later = sim.render_camera()
    assert all(type(f) is DrawingFrame for f in early) and type(later) is CameraFrame
    for frame, rgb in zip(early, expected, strict=True):
        assert np.array_equal(frame.rgb, rgb)
    assert not np.array_equal(later.rgb, expected[-1])
    renderer.close()
    sim.close()


def test_an_empty_noisy_window_reads_nothing_and_draws_as_a_frame() -> None:
    """A noisy camera's look at an empty window: no reading, and the generator draws as
    for a whole frame (the next frame is the same as after one)."""
    scene = load_scene(
        Path(__file__).parent.parent / "smccli/bench/scenes/bench_pick_realistic/scene.yaml"
    )
    sim = Sim(scene)
    after = []
    for look in (None, (10, 10, 5, 50)):
        sim.reset(noise_seed=5)
        first = sim.render_camera(look)
        after.append(sim.render_camera())
    assert not first.depth.any() and not first.rgb.any()
    assert np.array_equal(after[0].depth, after[1].depth)
    assert np.array_equal(after[0].rgb, after[1].rgb)
    sim.close()
