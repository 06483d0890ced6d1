"""The user guides, built and run exactly as they are written (:mod:`guides`).

"Bringing your own arm" (``docs/robots.md``) imports robosuite's UR5e with the xArm tendon
gripper as shipped and teaches it, then builds a 5-dof arm with a one-jaw gripper whose
objects lie nearer its base than the old crop box reached, and a scene with no
``perception`` setting. Each command must succeed and each campaign reach 95 % of at
least 40 trials. "Teach your own task": ``test_guide_own_task.py``.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import REPO, smc
from guides import run_guide_as_written, write_guide_files

GUIDES = {"own_arm": REPO / "docs" / "robots.md"}


@pytest.mark.slow
def test_own_arm_guide_runs_as_written(tmp_path: Path, vendor_models: Path) -> None:
    """docs/robots.md, its vendor robot imported from where `make models` put the files."""
    run_guide_as_written(GUIDES["own_arm"], tmp_path, smc, {"SMC_MODELS": str(vendor_models)})


def test_a_crop_box_that_cuts_an_object_is_warned_by_record_doctor_and_compile(
    tmp_path: Path,
) -> None:
    """The guide's arm with a scene whose own crop box starts inside the cube (x 0.10-0.13
    m at the nominal layout): each step names the face and the setting."""
    files = write_guide_files(GUIDES["own_arm"], tmp_path)
    scene = files["five_pick/scene.yaml"]
    assert "perception" not in scene.read_text()  # the guide's scene sets no crop
    scene.write_text(scene.read_text() + "perception:\n  crop_min: [0.12, -0.65, -0.05]\n")
    said = "reaches the crop box's x_min face (x = 0.120 m)"

    def record(out: str):
        demo = files["five_pick/demo.yaml"]
        return smc("record", "--scene", scene, "--script", demo, "-o", out, cwd=tmp_path)

    proc = record("d.mcap")
    assert proc.returncode == 0 and said in proc.stderr and "perception.crop_min" in proc.stderr, (
        proc.stderr
    )
    proc = smc("doctor", "d.mcap", cwd=tmp_path)
    assert proc.returncode == 1 and "x_min face" in proc.stdout, proc.stdout
    proc = smc("compile", "d.mcap", "-o", "t.json", cwd=tmp_path)
    assert proc.returncode == 0 and said in proc.stderr, proc.stderr
    # Without the scene's box the cube is whole: no warning at all.
    scene.write_text(scene.read_text().split("perception:")[0])
    proc = record("e.mcap")
    assert proc.returncode == 0 and "warning" not in proc.stderr, proc.stderr


def test_replay_notes_a_scene_file_edited_after_teaching(tmp_path: Path) -> None:
    """Without --scene a tree runs the copy of its scene it carries; once the scene file it
    was taught from has changed, replay says so (and --scene runs the file as it is)."""
    files = write_guide_files(GUIDES["own_arm"], tmp_path)
    scene, demo = files["five_pick/scene.yaml"], files["five_pick/demo.yaml"]
    assert (
        smc("record", "--scene", scene, "--script", demo, "-o", "d.mcap", cwd=tmp_path).returncode
        == 0
    )
    assert smc("compile", "d.mcap", "-o", "t.json", cwd=tmp_path).returncode == 0
    proc = smc("replay", "t.json", cwd=tmp_path)
    assert proc.returncode == 0 and "has changed since" not in proc.stdout + proc.stderr
    scene.write_text(scene.read_text().replace("x: [0.09, 0.14]", "x: [0.09, 0.16]"))
    proc = smc("replay", "t.json", cwd=tmp_path)
    said = f"{scene.resolve()} has changed since (--scene to run it as it is now)"
    assert proc.returncode == 0 and said in proc.stdout + proc.stderr, proc.stdout + proc.stderr
