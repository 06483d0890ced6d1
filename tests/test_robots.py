"""Robots as data: built-in robot files, a user's own robot end to end, broken robot files,
and trees that know the robot they were taught on."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import mujoco
import pytest
from conftest import REPO, SAMPLE_LOGS, sha256, smc

from smccli.errors import LogError, SceneError
from smccli.learn.compile import compile_logs
from smccli.logs import read_log
from smccli.world.robot import builtin_robot_names, kinematics_digest, load_robot
from smccli.world.scene import load_scene, robot_identity, scene_of_log

TESTS = Path(__file__).resolve().parent
SIX = TESTS / "robots" / "six"
SIX_SCENE = TESTS / "scenes" / "six_pick" / "scene.yaml"
CLUTTER = TESTS / "scenes" / "bench_pick_clutter" / "scene.yaml"


def test_smc_robots_lists_two_arms() -> None:
    proc = smc("robots")
    assert proc.returncode == 0, proc.stderr
    rows = [line for line in proc.stdout.splitlines() if line.startswith("│")]
    names = [r.split("│")[1].strip() for r in rows]
    assert {"arm", "panda"} <= set(names), proc.stdout
    for row in rows:
        if row.split("│")[1].strip() in ("arm", "panda"):
            assert row.split("│")[2].strip() == "7", row
            assert "2 fingers" in row and "joint encoders" in row, row


def test_smc_robots_checks_a_users_robot_file(tmp_path: Path) -> None:
    proc = smc("robots", SIX / "robot.yaml")
    assert proc.returncode == 0, proc.stderr
    rows = [line for line in proc.stdout.splitlines() if line.startswith("│")]
    assert any(line.split("│")[1].strip() == "six" for line in rows)
    old, new, parts = BROKEN_ROBOTS["unknown-site"]
    _broken_copy(tmp_path, old, new)
    robot_file = tmp_path / "robots" / "six" / "robot.yaml"
    proc = smc("robots", robot_file)
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert str(robot_file) in lines[0] and all(p in lines[0] for p in parts), lines[0]


@pytest.mark.parametrize("name", builtin_robot_names())
def test_builtin_robots_fit_their_mjcf(name: str) -> None:
    robot = load_robot(name)
    model = mujoco.MjModel.from_xml_path(str(robot.mjcf_path))
    assert model.njnt == len(robot.joint_names)
    # Every robot geom is in the robot's group: what the lidar and the self-filter skip.
    assert set(model.geom_group.tolist()) == {robot.geom_group}


def test_kinematics_digest_is_that_of_the_robot_not_of_the_scene() -> None:
    arm_alone = load_robot("arm")
    alone = kinematics_digest(arm_alone, mujoco.MjModel.from_xml_path(str(arm_alone.mjcf_path)))
    in_scenes = {robot_identity(load_scene(s))["kinematics"] for s in ("bench_pick", "pick_place")}
    assert in_scenes == {alone}
    panda = robot_identity(load_scene("bench_pick_panda"))
    assert panda["name"] == "panda" and panda["kinematics"] != alone


def test_panda_has_the_panda_kinematics() -> None:
    """Franka's modified DH parameters (a, d, alpha) reproduce the model's flange pose."""
    import numpy as np

    dh = [
        (0, 0.333, 0),
        (0, 0, -np.pi / 2),
        (0, 0.316, np.pi / 2),
        (0.0825, 0, np.pi / 2),
        (-0.0825, 0.384, -np.pi / 2),
        (0, 0, np.pi / 2),
        (0.088, 0, np.pi / 2),
    ]

    def craig(a: float, d: float, alpha: float, theta: float) -> np.ndarray:
        ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
        return np.array(
            [
                [ct, -st, 0, a],
                [st * ca, ct * ca, -sa, -sa * d],
                [st * sa, ct * sa, ca, ca * d],
                [0, 0, 0, 1],
            ]
        )

    robot = load_robot("panda")
    model = mujoco.MjModel.from_xml_path(str(robot.mjcf_path))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    link7 = model.body(model.jnt_bodyid[model.joint(robot.arm_joints[-1]).id]).id
    for _ in range(10):
        lo, hi = model.jnt_range[:7, 0], model.jnt_range[:7, 1]
        q = rng.uniform(lo, hi)
        data.qpos[:7] = q
        mujoco.mj_kinematics(model, data)
        T = np.eye(4)
        for (a, d, alpha), theta in zip(dh, q, strict=True):
            T = T @ craig(a, d, alpha, theta)
        flange = T @ np.array([0, 0, 0.107, 1])
        R7 = data.xmat[link7].reshape(3, 3)
        model_flange = data.xpos[link7] + R7 @ np.array([0, 0, 0.107])
        np.testing.assert_allclose(model_flange, flange[:3], atol=1e-9)
    limits = {n: tuple(model.jnt_range[model.joint(n).id]) for n in robot.arm_joints}
    assert limits["joint4"] == pytest.approx((-3.0718, -0.0698))
    assert limits["joint6"] == pytest.approx((-0.0175, 3.7525))


# --- a robot of the user's own, end to end -------------------------------------------------


@pytest.mark.slow
def test_bring_your_own_robot_records_compiles_and_replays(tmp_path: Path) -> None:
    """A 6-dof arm that lives only in the test folder, with names of its own."""
    log, tree = tmp_path / "six.mcap", tmp_path / "six.json"
    script = SIX_SCENE.parent / "demo.yaml"
    proc = smc("record", "--scene", SIX_SCENE, "--script", script, "-o", log)
    assert proc.returncode == 0, proc.stderr
    assert read_log(log).attachments["robot.yaml"].decode() == (SIX / "robot.yaml").read_text()
    proc = smc("compile", log, "-o", tree)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(tree.read_text())
    assert doc["robot"]["name"] == "six"
    report = tmp_path / "campaign.json"
    proc = smc("replay", tree, "--scene", SIX_SCENE, "--trials", "6", "--report", report)
    summary = json.loads(report.read_text())
    assert proc.returncode == 0, proc.stderr
    assert summary["successes"] == 6, summary["failures"]
    # Its joints, not the arm's, are what the replay log carries.
    replay_log = tmp_path / "replay.mcap"
    proc = smc("replay", tree, "--scene", SIX_SCENE, "--seed", "4", "-o", replay_log)
    assert proc.returncode == 0, proc.stderr
    names = read_log(replay_log).joint_states[0].names
    assert tuple(names) == load_robot(SIX / "robot.yaml").joint_names


BROKEN_ROBOTS = {
    # case: (old, new, what the one line names)
    "unknown-joint": (
        "wrist_pitch, wrist_rotate]",
        "wrist_pich, wrist_rotate]",
        ["arm.joints[4] (line 6)", "no joint 'wrist_pich' in robot.xml", "joints: shoulder_pan"],
    ),
    "unknown-site": (
        "poi: tcp",
        "poi: tool_tip",
        ["poi (line 9)", "no site 'tool_tip'", "sites: tcp"],
    ),
    "unknown-actuator": (
        "actuator: jaw",
        "actuator: claw",
        ["gripper.actuator (line 12)", "no actuator 'claw'", "actuators: m_pan"],
    ),
    "home-length": (
        "home: [0.0, 0.2, 1.9, 0.0, 1.04, 0.0]",
        "home: [0.0, 0.2, 1.9, 0.0, 1.04]",
        ["arm.home (line 8)", "5 values for 6 arm joints"],
    ),
    "home-outside-limits": (
        "home: [0.0, 0.2, 1.9,",
        "home: [0.0, 2.2, 1.9,",
        ["arm.home[1] (line 8)", "outside shoulder_lift's limits [-1.9, 1.9]"],
    ),
    "schema": ("  actuator: jaw\n", "", ["gripper (line 11)", "actuator"]),
    "base-joint": (
        "geom_group: 3",
        "base: {joints: [x, y, yaw], actuators: [ax, ay, ayaw]}\ngeom_group: 3",
        ["base.joints[0] (line 14)", "no joint 'x' in robot.xml"],
    ),
    "geom-group": (
        "geom_group: 3",
        "geom_group: 2",
        ["geom_group (line 14)", "is in group 3, not 2"],
    ),
    "home-gripper-up": (
        "home: [0.0, 0.2, 1.9, 0.0, 1.04, 0.0]",
        "home: [0.0, 0.2, 1.9, 0.0, -1.5, 0.0]",
        ["arm.home (line 8)", "points 146 deg from straight down", "gripper pointing down"],
    ),
    "joints-out-of-order": (
        "wrist_roll, wrist_pitch, wrist_rotate]\n  actuators: [m_pan, m_lift, m_elbow, m_roll, "
        "m_pitch, m_rotate]\n  home: [0.0, 0.2, 1.9, 0.0, 1.04, 0.0]",
        "wrist_roll, wrist_rotate, wrist_pitch]\n  actuators: [m_pan, m_lift, m_elbow, m_roll, "
        "m_rotate, m_pitch]\n  home: [0.0, 0.2, 1.9, 0.0, 0.0, 1.04]",
        ["arm.joints (line 6)", "'wrist_pitch' does not roll the gripper", "ending with"],
    ),
}
BROKEN_MJCF = {
    # case: (old, new in robot.xml, what the one line names)
    "roll-flipped": (
        '<joint name="wrist_rotate" type="hinge" axis="0 0 1"',
        '<joint name="wrist_rotate" type="hinge" axis="0 0 -1"',
        ["arm.joints (line 6)", "'wrist_rotate' rolls the gripper the other way", "flip"],
    ),
    "pan-upside-down": (
        '<joint name="shoulder_pan" type="hinge" axis="0 0 1"',
        '<joint name="shoulder_pan" type="hinge" axis="0 0 -1"',
        ["arm.joints (line 6)", "'shoulder_pan' turns about [0.00, 0.00, -1.00]", "flip"],
    ),
}


def _broken_copy(tmp_path: Path, old: str, new: str) -> Path:
    """The six robot and its scene copied to ``tmp_path``, the robot file edited."""
    shutil.copytree(SIX, tmp_path / "robots" / "six")
    scene_dir = tmp_path / "scenes" / "six_pick"
    scene_dir.mkdir(parents=True)
    text = SIX_SCENE.read_text().replace("mjcf: ../../../smccli", f"mjcf: {REPO}/smccli")
    (scene_dir / "scene.yaml").write_text(text)
    robot = tmp_path / "robots" / "six" / "robot.yaml"
    assert old in robot.read_text(), old
    robot.write_text(robot.read_text().replace(old, new, 1))
    return scene_dir / "scene.yaml"


@pytest.mark.parametrize("case", sorted(BROKEN_ROBOTS))
def test_broken_robot_file_gets_one_line(tmp_path: Path, case: str) -> None:
    old, new, parts = BROKEN_ROBOTS[case]
    scene = _broken_copy(tmp_path, old, new)
    robot_file = tmp_path / "robots" / "six" / "robot.yaml"
    with pytest.raises(SceneError) as err:
        load_scene(scene)
    message = str(err.value)
    assert message.startswith(f"{robot_file}: "), message
    for part in parts:
        assert part in message, (part, message)


@pytest.mark.parametrize("case", sorted(BROKEN_MJCF))
def test_robot_whose_axes_break_the_controllers_assumptions_gets_one_line(
    tmp_path: Path, case: str
) -> None:
    """A wrist roll of the other sign or an upside-down pan: `smc robots` says what to fix
    (before, both passed and every target later read "out of the robot's reach")."""
    old, new, parts = BROKEN_MJCF[case]
    _broken_copy(tmp_path, "geom_group: 3", "geom_group: 3")
    xml = tmp_path / "robots" / "six" / "robot.xml"
    assert old in xml.read_text(), old
    xml.write_text(xml.read_text().replace(old, new, 1))
    robot_file = tmp_path / "robots" / "six" / "robot.yaml"
    proc = smc("robots", robot_file)
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"error: {robot_file}: "), lines[0]
    assert all(p in lines[0] for p in parts), lines[0]


def test_unreachable_target_says_what_fails() -> None:
    """Position (by how much) or orientation, and the joints the IK left at a limit."""
    import numpy as np

    from smccli.world.controller import reach_problem

    robot = load_robot("arm")
    model = mujoco.MjModel.from_xml_path(str(robot.mjcf_path))
    assert reach_problem(model, robot, np.array([0.5, 0.0, 0.1, 0.3])) is None
    far = reach_problem(model, robot, np.array([2.0, 0.0, 0.1, 0.0]))
    assert far is not None and far.startswith("the position stays 11"), far
    near = reach_problem(model, robot, np.array([0.05, 0.0, 0.05, 0.0]))
    assert near is not None and "at its upper limit" in near, near


def test_broken_robot_file_through_the_cli(tmp_path: Path) -> None:
    old, new, parts = BROKEN_ROBOTS["unknown-joint"]
    scene = _broken_copy(tmp_path, old, new)
    out = tmp_path / "demo.mcap"
    proc = smc("record", "--scene", scene, "--script", SIX_SCENE.parent / "demo.yaml", "-o", out)
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2 and len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert str(tmp_path / "robots" / "six" / "robot.yaml") in lines[0]
    assert all(p in lines[0] for p in parts), lines[0]
    assert not out.exists() and not Path(str(out) + ".part").exists()


# --- trees know their robot -----------------------------------------------------------------


@pytest.fixture(scope="module")
def bench_tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The paper's one demonstration (a log from before robot files: no robot.yaml)."""
    path = tmp_path_factory.mktemp("robots") / "bench.json"
    compile_logs(sorted((SAMPLE_LOGS / "bench_pick").glob("*.mcap")), path)
    return path


def test_old_logs_hold_the_arm(bench_tree: Path) -> None:
    log = read_log(SAMPLE_LOGS / "bench_pick" / "demo.mcap")
    assert "robot.yaml" not in log.attachments
    assert scene_of_log(log.attachments, log.path).robot.name == "arm"
    doc = json.loads(bench_tree.read_text())
    assert doc["robot"] == robot_identity(load_scene("bench_pick"))
    assert doc["scene"]["sensors"]["camera"] == {"width": 320, "height": 240, "fovy": 55.0}


@pytest.mark.slow
def test_tree_runs_in_a_cluttered_copy_of_its_scene(bench_tree: Path, tmp_path: Path) -> None:
    """Same robot, same camera, three distractors: allowed with a note, and it succeeds."""
    report = tmp_path / "clutter.json"
    proc = smc("replay", bench_tree, "--scene", CLUTTER, "--trials", "10", "--report", report)
    summary = json.loads(report.read_text())
    assert proc.returncode == 0, proc.stderr
    assert "taught in scene 'bench_pick', running in 'bench_pick_clutter'" in summary["note"]
    assert "note: taught in scene" in proc.stdout
    assert summary["successes"] == 10, summary["failures"]


@pytest.mark.parametrize("scene", ["bench_pick_panda", str(SIX_SCENE)])
def test_tree_is_refused_on_another_robot(bench_tree: Path, tmp_path: Path, scene: str) -> None:
    out = tmp_path / "replay.mcap"
    before = sha256(bench_tree)
    proc = smc("replay", bench_tree, "--scene", scene, "-o", out)
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2 and len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert "taught on robot 'arm'" in lines[0] and "holds robot" in lines[0], lines[0]
    assert not out.exists() and sha256(bench_tree) == before


def test_tree_is_refused_with_other_sensors(bench_tree: Path, tmp_path: Path) -> None:
    scene = tmp_path / "scene.yaml"
    text = CLUTTER.read_text().replace("mjcf: ../../../smccli", f"mjcf: {REPO}/smccli")
    scene.write_text(text.replace("width: 320, height: 240", "width: 640, height: 480"))
    proc = smc("replay", bench_tree, "--scene", scene)
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert "320x240 camera" in lines[0] and "640x480" in lines[0], lines[0]


def test_compile_refuses_a_log_of_another_robot(bench_tree: Path, tmp_path: Path) -> None:
    tree = tmp_path / "tree.json"
    shutil.copy(bench_tree, tree)
    before = sha256(tree)
    panda_log = SAMPLE_LOGS / "bench_pick_panda" / "demo.mcap"
    with pytest.raises(LogError, match="recorded with robot 'panda'.*taught on 'arm'"):
        compile_logs([panda_log], tree)
    assert sha256(tree) == before


# --- the Panda ------------------------------------------------------------------------------


@pytest.mark.slow
def test_panda_sample_demo_compiles_and_replays(tmp_path: Path) -> None:
    tree = tmp_path / "panda.json"
    compile_logs([SAMPLE_LOGS / "bench_pick_panda" / "demo.mcap"], tree)
    assert json.loads(tree.read_text())["robot"]["name"] == "panda"
    report = tmp_path / "panda_campaign.json"
    proc = smc("replay", tree, "--trials", "8", "--report", report)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(report.read_text())
    assert summary["scene"] == "bench_pick_panda" and summary["successes"] == 8, summary
