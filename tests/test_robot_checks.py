"""``smc robots`` in simulation (:mod:`smccli.world.robot_checks`): every check passes on
the built-in robots, the user's six and the guide's five in their scenes, and fails with
its one line and exit 2 on a copy broken the way issue 37's robots were (a tendon gripper
commanded in the wrong units, swapped commands, a home posture in the table or in the
camera's view, a POI off the pads, an object range out of reach)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from conftest import REPO, smc
from guides import write_guide_files

from smccli.world.robot import builtin_robot_names, load_robot
from smccli.world.robot_checks import REACH_BUDGET, reach_targets, simulation_checks
from smccli.world.scene import builtin_names, load_scene

TESTS = Path(__file__).resolve().parent
SIX = TESTS / "robots" / "six"
SIX_SCENE = TESTS / "scenes" / "six_pick" / "scene.yaml"
CHECKS = ["gripper", "home_contacts", "home_view", "reach", "poi"]

TENDON = (
    '    <position name="jaw" joint="jaw_a_slide" ctrlrange="0 0.045" kp="1000" dampratio="1"\n'
    '              forcelimited="true" forcerange="-40 40"/>',
    # As Menagerie's Panda hand drives its fingers: a tendon, commands 0-255.
    '    <general name="jaw" tendon="split" ctrlrange="0 255" forcerange="-40 40"\n'
    '             gainprm="0.35294 0 0" biastype="affine" biasprm="0 -2000 -60"/>\n'
    "  </actuator>\n"
    '  <tendon><fixed name="split"><joint joint="jaw_a_slide" coef="0.5"/>'
    '<joint joint="jaw_b_slide" coef="0.5"/></fixed></tendon>\n'
    "  <actuator>",
)
# Home postures of six found by its IK (gripper down, yaw 0): the POI 12 cm above the
# white box's range (in the camera's view) and at the table top (the fingers in it).
HOME = "home: [0.0, 0.2, 1.9, 0.0, 1.04, 0.0]"
IN_VIEW = "home: [-0.219, 0.549, 1.981, 0.0, 0.613, -0.219]"
IN_TABLE = "home: [-0.927, 0.861, 1.834, 0.0, 0.447, -0.927]"
TCP = '<site name="tcp" pos="0 0 0.135"'

BROKEN = {
    # case: (file, old, new, check, what the line says)
    "tendon-units": ("robot.xml", *TENDON, "gripper", "takes commands in [0, 255]"),
    "swapped": (
        "robot.yaml",
        "opening: [0.0, 0.045]",
        "opening: [0.045, 0.0]",
        "gripper",
        "swapped: swap gripper.opening",
    ),
    "home-in-table": ("robot.yaml", HOME, IN_TABLE, "home_contacts", "touches 'table_top'"),
    "home-in-view": ("robot.yaml", HOME, IN_VIEW, "home_view", "of where white_box lies"),
    "poi-off-the-pads": (
        "robot.xml",
        TCP,
        '<site name="tcp" pos="0 0.035 0.135"',
        "poi",
        "move site 'tcp' +35 mm along its y axis",
    ),
    "poi-beyond-the-tips": (
        "robot.xml",
        TCP,
        '<site name="tcp" pos="0 0 0.2"',
        "poi",
        "outside the pads along its approach",
    ),
    "range-out-of-reach": (
        "scene.yaml",
        "x: [0.35, 0.6]",
        "x: [0.35, 1.1]",
        "reach",
        "worst: white_box at (1.10",
    ),
}


def _broken_six(tmp_path: Path, file: str, old: str, new: str) -> tuple[Path, Path]:
    """The six robot and its scene copied to ``tmp_path``, one file edited: (robot file,
    scene file)."""
    shutil.copytree(SIX, tmp_path / "robots" / "six")
    scene = tmp_path / "scenes" / "six_pick" / "scene.yaml"
    scene.parent.mkdir(parents=True)
    scene.write_text(SIX_SCENE.read_text().replace("mjcf: ../../../smccli", f"mjcf: {REPO}/smccli"))
    edited = scene if file == "scene.yaml" else tmp_path / "robots" / "six" / file
    assert old in edited.read_text(), old
    edited.write_text(edited.read_text().replace(old, new, 1))
    return tmp_path / "robots" / "six" / "robot.yaml", scene


def _statuses(findings) -> dict[str, str]:
    return {f.check: f.status for f in findings}


@pytest.mark.parametrize("name", builtin_robot_names())
def test_builtin_robots_pass_alone(name: str) -> None:
    findings = simulation_checks(load_robot(name))
    assert [f.check for f in findings] == CHECKS
    assert "fail" not in _statuses(findings).values(), findings
    if name != "base":  # an arm with a gripper: measured, not skipped
        assert _statuses(findings)["gripper"] == _statuses(findings)["poi"] == "pass", findings


@pytest.mark.parametrize("name", [*builtin_names(), "six_pick", "bench_pick_clutter", "mug_place"])
def test_robots_pass_in_their_scenes(name: str) -> None:
    scene = load_scene(name if name in builtin_names() else TESTS / "scenes" / name / "scene.yaml")
    findings = simulation_checks(scene.robot, scene)
    statuses = _statuses(findings)
    assert "fail" not in statuses.values(), findings
    if scene.robot.base is None:  # an arm on a table: every check ran
        assert set(statuses.values()) == {"pass"}, findings


def test_the_guides_five_passes_in_its_scene(tmp_path: Path) -> None:
    """docs/robots.md's one-jaw arm: the POI between the fixed and the moving jaw, home
    swung to the side out of the camera's view of the cube."""
    files = write_guide_files(REPO / "docs" / "robots.md", tmp_path)
    scene = load_scene(files["five_pick/scene.yaml"])
    findings = simulation_checks(scene.robot, scene)
    assert set(_statuses(findings).values()) == {"pass"}, findings
    poi = next(f for f in findings if f.check == "poi")
    assert "'f5_fixed_jaw'" in poi.measured and "'f5_moving_jaw_pad'" in poi.measured, poi


def test_reach_samples_a_few_hundred_places_at_most() -> None:
    for name in builtin_names():
        assert len(reach_targets(load_scene(name))) <= REACH_BUDGET + 10


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_a_broken_robot_fails_its_check_in_one_line(tmp_path: Path, case: str) -> None:
    file, old, new, check, says = BROKEN[case]
    robot, scene = _broken_six(tmp_path, file, old, new)
    proc = smc("robots", "--scene", scene)
    errors = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2 and len(errors) == 1, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    named = scene if check == "reach" else robot  # the file to change
    assert errors[0].startswith(f"error: {named}: {check}: "), errors[0]
    assert says in errors[0], errors[0]
    # The same finding as data, from the library.
    findings = simulation_checks(load_scene(scene).robot, load_scene(scene))
    assert [f.check for f in findings if f.status == "fail"] == [check], findings
    failed = next(f for f in findings if f.check == check)
    assert failed.fix and failed.measured


def test_a_robot_file_alone_is_checked_on_a_table_and_its_gripper_measured(
    tmp_path: Path,
) -> None:
    """Without --scene: the gripper, home's contacts and the POI; reach and the camera's
    view need a scene and say so."""
    proc = smc("robots", SIX / "robot.yaml")
    assert proc.returncode == 0, proc.stderr
    assert "alone on a table" in proc.stdout and "FAIL" not in proc.stdout
    findings = simulation_checks(load_robot(SIX / "robot.yaml"))
    assert _statuses(findings) == {
        "gripper": "pass",
        "home_contacts": "pass",
        "home_view": "skip",
        "reach": "skip",
        "poi": "pass",
    }
    gripper = findings[0]
    assert "jaw_a_slide 45.0 mm of 45.0 mm" in gripper.measured, gripper
    robot, _ = _broken_six(tmp_path, *BROKEN["tendon-units"][:3])
    proc = smc("robots", robot)
    errors = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2 and len(errors) == 1, proc.stderr
    assert errors[0].startswith(f"error: {robot}: gripper: "), errors[0]
    assert "jaw_a_slide -0.0 mm of 45.0 mm" in errors[0] or "jaw_a_slide 0.0 mm" in errors[0]
