"""The ``smc`` entry point itself: help, scenes, and error mapping."""

from __future__ import annotations

import pytest
from conftest import smc


def test_help_lists_the_commands():
    proc = smc("--help")
    assert proc.returncode == 0
    for cmd in ("record", "compile", "replay", "inspect", "scenes"):
        assert cmd in proc.stdout


def test_scenes_lists_objects_sensors_and_variants():
    proc = smc("scenes")
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    for name in (
        "pick_place",
        "weigh_sort",
        "bench_pick",
        "orange_cube",
        "white_box",
        "scale",
        "cube_green",
        "camera 320x240",
    ):
        assert name in out


@pytest.mark.parametrize(
    "args, needle",
    [
        (
            ("record", "--scene", "no_such_scene", "--script", "x.yaml", "-o", "/tmp/never.mcap"),
            "no_such_scene",
        ),
        (("replay", "/nonexistent/tree.json"), "tree.json"),
        (("compile", "/nonexistent/demo.mcap", "-o", "/tmp/never_tree.json"), "demo.mcap"),
    ],
)
def test_expected_failures_are_one_line_exit_2(args, needle):
    proc = smc(*args)
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in proc.stderr


def test_usage_error_is_reported_by_typer():
    proc = smc("compile")  # LOGS missing
    assert proc.returncode == 2 and "Missing argument" in proc.stderr
