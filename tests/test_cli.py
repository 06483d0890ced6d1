"""The ``smc`` entry point itself: help, scenes, and error mapping."""

from __future__ import annotations

from pathlib import Path

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
        (("run", "tree.json", "--ros1", "--topics", "/nonexistent/map.yaml"), "map.yaml"),
        (("run", "tree.json", "--topics", "map.yaml"), "--ros1"),
        (("sim", "--ros1", "--scene", "no_such_scene"), "no_such_scene"),
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


def _foreign_mcap(path) -> None:
    """An MCAP file of somebody else's: one JSON message, no smc metadata, no scene."""
    from mcap.writer import Writer

    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        schema = w.register_schema("x", "jsonschema", b"{}")
        channel = w.register_channel("/foo", "json", schema)
        w.add_message(channel, 0, b"{}", 0)
        w.finish()


def test_warnings_and_errors_are_one_line_each_off_a_terminal(tmp_path, sample_trees):
    """Piped stderr (CI, log files) and no COLUMNS: rich would wrap at 80 columns, cutting
    the path in two, and a progress display would leave a blank line. Each warning and the
    error are one whole line, the error last."""
    import os
    import subprocess
    import sys

    from conftest import REPO

    log = tmp_path / ("a_folder_with_a_rather_long_name_" * 2) / "foreign_recording_of_a_lab.mcap"
    _foreign_mcap(log)
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    env.setdefault("MUJOCO_GL", "egl")

    def run(*args) -> subprocess.CompletedProcess[str]:
        cmd = [sys.executable, "-m", "smccli.cli", *map(str, args)]
        return subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=REPO)

    compiled = run("compile", log, "-o", tmp_path / "tree.json")
    inspected = run("inspect", sample_trees["bench_pick"], log, "--save", tmp_path / "x.rrd")
    for proc, code, last in ((compiled, 2, "error: "), (inspected, 0, "warning: ")):
        lines = proc.stderr.split("\n")
        assert lines[-1] == "" and "" not in lines[:-1], proc.stderr  # no blank line
        lines = lines[:-1]
        assert proc.returncode == code, proc.stderr
        assert lines and all(ln.startswith(("warning: ", "error: ")) for ln in lines), lines
        assert lines[-1].startswith(last)
        assert all(str(log) in ln or log.name in ln for ln in lines), lines
        assert any(len(ln) > 120 for ln in lines)


def test_help_says_what_compile_and_doctor_read():
    """compile and doctor read bags too (with --topics), and compile's --workers help gives
    the number of logs below which compile stays in one process."""
    from smccli.learn.compile import PARALLEL_MIN_LOGS

    helps = {c: " ".join(smc(c, "--help").stdout.split()) for c in ("compile", "doctor")}
    for text in helps.values():
        assert "rosbag2 folder" in text and "ROS 1 .bag" in text, text
    assert f"none below {PARALLEL_MIN_LOGS} logs" in helps["compile"], helps["compile"]


REPLAY_OPTIONS = dict(
    tree=Path("tree.json"), trials=0, workers=0, cluster=None, teach=None, script=None, verify=None
)


@pytest.mark.parametrize(
    "options, kind",
    [
        ({}, "episode"),
        ({"trials": 5}, "campaign"),
        ({"trials": 5, "cluster": "tcp://h:8786"}, "campaign"),
        ({"teach": "script", "script": Path("s.yaml")}, "episode"),
        ({"tree": None, "verify": Path("demo.mcap")}, "verify"),
    ],
)
def test_replay_kind_of_the_options(options, kind):
    from smccli.execute.replay_command import replay_kind

    assert replay_kind(**(REPLAY_OPTIONS | options)) == kind


@pytest.mark.parametrize(
    "options, needle",
    [
        ({"verify": Path("demo.mcap")}, "give no tree or --trials"),
        ({"tree": None}, "needs a tree file"),
        ({"teach": "script", "trials": 5}, "does not go with --trials"),
        ({"script": Path("s.yaml")}, "continuation of --teach script"),
        ({"cluster": "tcp://h:8786"}, "give --trials N"),
        ({"cluster": "tcp://h:8786", "trials": 5, "workers": 2}, "--workers counts local"),
    ],
)
def test_replay_refuses_options_that_mean_nothing(options, needle):
    from smccli.errors import SmcError
    from smccli.execute.replay_command import replay_kind

    with pytest.raises(SmcError, match=needle):
        replay_kind(**(REPLAY_OPTIONS | options))
