"""``smc record`` end to end: the log's contents and schemas, crash safety, errors."""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import SAMPLE_LOGS
from mcap.reader import make_reader

from smccli.errors import OutputExistsError
from smccli.logs import read_log
from smccli.record import RecordConfig, record

SCRIPT = SAMPLE_LOGS / "pick_place" / "demo1.yaml"
PROTO = {
    "/robot/joint_states",
    "/robot/poi",
    "/camera/color",
    "/camera/depth",
    "/camera/calibration",
    "/tf",
    "/perception/points",
}
JSON = {"/teleop/command", "/saliency", "/sim/ground_truth"}


def smc(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "smccli.cli", *args], capture_output=True, text=True, timeout=timeout
    )


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("rec") / "x.mcap"
    proc = smc(
        "record",
        "--scene",
        "pick_place",
        "--operator",
        "script",
        "--script",
        str(SCRIPT),
        "-o",
        str(out),
    )
    assert proc.returncode == 0, proc.stderr
    assert "wrote" in proc.stdout and "/camera/color" in proc.stdout
    return out


def test_log_reads_with_crc_checks_and_holds_every_topic(recorded):
    with open(recorded, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        channels = {c.topic: c for c in summary.channels.values()}
        schemas = summary.schemas
        counts = {}
        for _, channel, _ in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        attachments = {a.name: a.data for a in reader.iter_attachments()}
    for topic in PROTO:
        assert schemas[channels[topic].schema_id].encoding == "protobuf", topic
        assert schemas[channels[topic].schema_id].name.startswith("foxglove."), topic
        assert channels[topic].message_encoding == "protobuf"
    for topic in JSON:
        assert schemas[channels[topic].schema_id].encoding == "jsonschema", topic
        assert channels[topic].message_encoding == "json"
    assert counts["/saliency"] == 2  # a mark after the grasp and after the release
    assert counts["/robot/joint_states"] > 500 and counts["/camera/color"] > 50
    assert meta["smc"]["scene"] == "pick_place" and meta["smc"]["operator"] == "script"
    assert meta["smc"]["scene_digest"].startswith("sha256:") and "seed" in meta["smc"]
    assert b"<mujoco" in attachments["scene.xml"] and b"orange_cube" in attachments["scene.yaml"]
    assert recorded.stat().st_size < 5e6


def test_rerun_imports_images_and_points(recorded):
    from rerun.chunk import McapReader

    columns: set[str] = set()
    for chunk in McapReader(str(recorded), timeline_type="duration_ns").stream():
        entity = chunk.entity_path
        for name in (
            chunk.component_descriptors() if hasattr(chunk, "component_descriptors") else []
        ):
            columns.add(f"{entity}|{name}")
        columns.add(f"{entity}|{chunk}")
    text = "\n".join(columns)
    assert "/camera/color" in text and "EncodedImage" in text
    assert "/perception/points" in text and "Points3D" in text


def test_same_script_and_seed_give_the_same_bytes(tmp_path):
    digests = []
    for name in ("a.mcap", "b.mcap"):
        record(
            RecordConfig(
                scene="bench_pick",
                script=SAMPLE_LOGS / "bench_pick" / "demo.yaml",
                seed=3,
                output=tmp_path / name,
                reproducible=True,
            )
        )
        digests.append(hashlib.sha256((tmp_path / name).read_bytes()).hexdigest())
    assert digests[0] == digests[1]


def test_existing_output_is_refused(recorded):
    with pytest.raises(OutputExistsError, match="--force"):
        record(RecordConfig(scene="pick_place", script=SCRIPT, output=recorded))


@pytest.mark.parametrize(
    "body, message",
    [
        ("scene: pick_place\nsteps:\n  - move_to: {object: purple_unicorn}\n", "purple_unicorn"),
        (
            "scene: pick_place\nsteps:\n  - move_to: {position: [2.5, 0, 0.2]}\n",
            "out of the robot's reach",
        ),
        ("scene: pick_place\nsteps:\n  - fly: {to: moon}\n", "step 0"),
        ("scene: pick_place\nsteps: [\n", "YAML"),
    ],
)
def test_bad_scripts_exit_2_with_one_line_and_no_log(tmp_path, body, message):
    script = tmp_path / "bad.yaml"
    script.write_text(body)
    out = tmp_path / "bad.mcap"
    proc = smc("record", "--scene", "pick_place", "--script", str(script), "-o", str(out))
    assert proc.returncode == 2
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and message in lines[0] and "bad.yaml" in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr
    assert not out.exists() and not (tmp_path / "bad.mcap.part").exists()


def test_unknown_scene_lists_the_valid_ones():
    with pytest.raises(Exception, match="pick_place"):
        record(RecordConfig(scene="nope", script=SCRIPT, output=Path("/tmp/never.mcap")))


def test_killed_recorder_loses_at_most_the_last_second(tmp_path):
    """kill -9 a real-time recording: the .part holds everything but the last ~second."""
    out = tmp_path / "killed.mcap"
    part = tmp_path / "killed.mcap.part"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "smccli.cli",
            "record",
            "--scene",
            "weigh_sort",
            "--script",
            str(SAMPLE_LOGS / "weigh_sort" / "demo_light.yaml"),
            "--realtime",
            "-o",
            str(out),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    deadline = time.monotonic() + 60
    while not part.exists():
        assert time.monotonic() < deadline and proc.poll() is None, "recorder did not start"
        time.sleep(0.02)
    t_open = time.monotonic()
    time.sleep(4.0)
    os.kill(proc.pid, signal.SIGKILL)
    elapsed = time.monotonic() - t_open
    proc.wait(timeout=10)
    assert not out.exists() and part.exists()
    warnings: list[str] = []
    log = read_log(part, on_warning=warnings.append)
    assert log.truncated and warnings and "killed.mcap.part" in warnings[0]
    t_last = max(log.poi_t[-1], log.commands[-1].t)
    # Sim time tracks wall time from the first tick (which follows the .part's creation
    # by the first render, < 0.5 s): what is lost is at most the last second.
    assert t_last >= elapsed - 0.5 - 1.0, (t_last, elapsed)
    assert len(log.frames) >= int(10 * (t_last - 0.2))
