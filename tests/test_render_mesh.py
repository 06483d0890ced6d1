"""The sensor camera draws a vendor's CAD meshes simplified (smccli/world/render_mesh.py):
at most RENDER_FACES triangles each, the same picture but along the robot's silhouette,
physics untouched."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from smccli.world import render_mesh
from smccli.world.render_mesh import RENDER_FACES, render_model
from smccli.world.scene import load_scene

SOARM = Path(__file__).resolve().parent / "scenes" / "soarm_pick" / "scene.yaml"


def _frame(model: mujoco.MjModel, data: mujoco.MjData, cam: str) -> tuple[np.ndarray, ...]:
    r = mujoco.Renderer(model, 240, 320)
    r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
    r.update_scene(data, camera=cam)
    rgb = r.render().copy()
    r.enable_depth_rendering()
    r.update_scene(data, camera=cam)
    depth = r.render().copy()
    r.close()
    return rgb, depth


@pytest.fixture(scope="module")
def soarm(vendor_models: Path) -> tuple[mujoco.MjModel, mujoco.MjData]:
    scene = load_scene(SOARM)
    model = scene.model()
    data = mujoco.MjData(model)
    for joint, q in zip(scene.robot.arm_joints, scene.robot.home, strict=True):
        data.qpos[model.jnt_qposadr[model.joint(joint).id]] = q
    mujoco.mj_forward(model, data)
    return model, data


def test_large_meshes_are_drawn_simplified_and_physics_keeps_them(soarm) -> None:
    model, _ = soarm
    assert model.mesh_facenum.max() > 10 * RENDER_FACES  # the shipped SO-ARM's CAD meshes
    before = model.mesh_vert.copy(), model.mesh_face.copy(), model.mesh_facenum.copy()
    drawn = render_model(model)
    assert drawn is not model
    assert drawn.mesh_facenum.max() <= RENDER_FACES
    assert drawn.mesh_facenum.sum() < model.mesh_facenum.sum() / 5
    # the model physics steps is not touched, and the copy's bodies and geoms are its own
    assert np.array_equal(model.mesh_vert, before[0])
    assert np.array_equal(model.mesh_face, before[1])
    assert np.array_equal(model.mesh_facenum, before[2])
    assert (drawn.nbody, drawn.ngeom, drawn.nq) == (model.nbody, model.ngeom, model.nq)
    assert np.array_equal(drawn.geom_size, model.geom_size)
    # the simplified surface lies on the shipped one: no vertex strays from its mesh's box
    for i in np.flatnonzero(model.mesh_facenum > RENDER_FACES):
        full = model.mesh_vert[
            model.mesh_vertadr[i] : model.mesh_vertadr[i] + model.mesh_vertnum[i]
        ]
        small = drawn.mesh_vert[
            drawn.mesh_vertadr[i] : drawn.mesh_vertadr[i] + drawn.mesh_vertnum[i]
        ]
        assert np.all(small >= full.min(axis=0) - 1e-4) and np.all(small <= full.max(axis=0) + 1e-4)
        normals = drawn.mesh_normal[drawn.mesh_normaladr[i] : drawn.mesh_normaladr[i] + len(small)]
        assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-3)


def test_the_sensor_sees_the_same_picture_but_along_the_silhouette(soarm) -> None:
    model, data = soarm
    rgb, depth = _frame(model, data, "sensor_camera")
    rgb_s, depth_s = _frame(render_model(model), data, "sensor_camera")
    robot_pixels = np.abs(depth - depth_s) > 0  # anything the simplification moved at all
    assert robot_pixels.any()  # the arm is in view, so this compares something
    colour = np.abs(rgb.astype(int) - rgb_s.astype(int)).max(axis=2) > 10
    assert colour.mean() < 0.02, colour.mean()  # measured: 0.6 % of the frame
    assert np.mean(np.abs(depth - depth_s) > 0.002) < 0.005


def test_simplifying_is_repeatable(soarm, tmp_path, monkeypatch) -> None:
    """A campaign's trials must see the same robot: the same surface from a cold cache,
    from the disk cache another command left, and from a cache file that went bad."""
    model, _ = soarm

    def drawn(cache: str):
        monkeypatch.setenv("SMC_CACHE_DIR", str(tmp_path / cache))
        render_mesh._SIMPLIFIED.clear()
        return render_model(model)

    def same(a, b) -> bool:
        return np.array_equal(a.mesh_vert, b.mesh_vert) and np.array_equal(a.mesh_face, b.mesh_face)

    first = drawn("a")
    files = sorted((tmp_path / "a" / "meshes").glob("*.npz"))
    assert files  # each simplified mesh kept on disk
    assert same(first, drawn("b"))  # cold again, elsewhere
    assert same(first, drawn("a"))  # read back from disk
    files[0].write_bytes(b"not a zip")
    assert same(first, drawn("a"))  # a bad file is simplified again ...
    with np.load(files[0]) as f:  # ... and replaced
        assert len(f["vertices"]) > 0


def test_a_model_of_small_meshes_is_drawn_as_it_is() -> None:
    model = load_scene("bench_pick").model()
    assert render_model(model) is model


def _grid_mesh_mjcf(textured: bool) -> str:
    """A 60 x 60 quad grid (7,200 triangles) with texture coordinates, drawn with a plain
    material or a textured one."""
    n = 61
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    verts = np.column_stack([0.1 * u.ravel(), 0.1 * v.ravel(), 0.01 * np.sin(6 * u.ravel())])
    faces = []
    for r in range(n - 1):
        for c in range(n - 1):
            a = r * n + c
            faces += [(a, a + 1, a + n), (a + 1, a + n + 1, a + n)]
    texcoord = np.column_stack([u.ravel(), v.ravel()])
    text = " ".join
    material = (
        '<texture name="t" type="2d" builtin="checker" width="8" height="8"/>'
        '<material name="m" texture="t"/>'
        if textured
        else '<material name="m" rgba="0.5 0.5 0.5 1"/>'
    )
    return f"""<mujoco><asset>{material}
      <mesh name="grid" vertex="{text(f"{x:.5f}" for x in verts.ravel())}"
            face="{text(str(i) for f in faces for i in f)}"
            texcoord="{text(f"{x:.5f}" for x in texcoord.ravel())}"/>
    </asset><worldbody><geom type="mesh" mesh="grid" material="m"/></worldbody></mujoco>"""


@pytest.mark.parametrize("textured", [False, True])
def test_texture_coordinates_no_texture_uses_do_not_keep_a_mesh_whole(textured: bool) -> None:
    """A vendor's OBJ meshes carry texture coordinates that no texture of theirs uses
    (robosuite's Panda: 50 of its 63 meshes); those are drawn simplified like any other.
    A mesh a textured material covers keeps its surface, coordinates and all."""
    model = mujoco.MjModel.from_xml_string(_grid_mesh_mjcf(textured))
    assert model.mesh_facenum[0] > RENDER_FACES and model.mesh_texcoordadr[0] != -1
    drawn = render_model(model)
    if textured:
        assert drawn is model
    else:
        assert drawn.mesh_facenum[0] <= RENDER_FACES and drawn.mesh_texcoordadr[0] == -1
        mujoco.Renderer(drawn, 48, 64).close()  # the GL context takes the copy
