"""``smc record`` end to end: the log's contents and schemas, crash safety, errors."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import SAMPLE_LOGS, sha256, smc
from mcap.reader import make_reader

from smccli.errors import OutputExistsError
from smccli.learn.compile import compile_logs
from smccli.logs import read_log
from smccli.record.session import RecordConfig, record, record_episodes

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
        digests.append(sha256(tmp_path / name))
    assert digests[0] == digests[1]


def _messages(path: Path) -> list[tuple[str, int, bytes]]:
    with path.open("rb") as f:
        return [(c.topic, m.log_time, m.data) for _, c, m in make_reader(f).iter_messages()]


def test_a_session_records_episodes_each_as_its_seed_alone(tmp_path):
    """``--episodes 2 --randomize --seed 3``: demo-000 is what ``--seed 3`` records alone,
    demo-001 starts from another layout (seed 4); one simulation serves both."""
    cfg = RecordConfig(
        scene="bench_pick",
        script=SAMPLE_LOGS / "bench_pick" / "demo.yaml",
        seed=3,
        randomize=True,
        reproducible=True,
    )
    alone = record(replace(cfg, output=tmp_path / "alone.mcap"))
    (tmp_path / "s-001.mcap").write_bytes(b"keep me")
    with pytest.raises(OutputExistsError, match="s-001.mcap"):
        record_episodes(replace(cfg, output=tmp_path / "s.mcap", episodes=2))
    assert not (tmp_path / "s-000.mcap").exists()  # refused before the first episode
    assert (tmp_path / "s-001.mcap").read_bytes() == b"keep me"
    (tmp_path / "s-001.mcap").unlink()
    kept = record_episodes(replace(cfg, output=tmp_path / "s.mcap", episodes=2))
    assert [s.path.name for s in kept] == ["s-000.mcap", "s-001.mcap"]
    assert _messages(kept[0].path) == _messages(alone.path)
    meta = [read_log(s.path).metadata for s in kept]
    assert [m["seed"] for m in meta] == ["3", "4"] and meta[1]["episode"] == "2/2"
    first = [read_log(s.path).ground_truth[0][1] for s in kept]
    assert not np.allclose(first[0]["white_box"], first[1]["white_box"])


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


def _start_recorder(out: Path, *extra: str) -> subprocess.Popen:
    """A real-time recording of the weigh_sort demo in a subprocess; stderr is a pipe, so
    the CLI prints one plain status line per simulated second."""
    return subprocess.Popen(
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
            *extra,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


STATUS = re.compile(r"recording: sim\s+([\d.]+) s\s+on disk\s+([\d.]+) s")


def _wait_until_sim_time(proc: subprocess.Popen, t: float) -> tuple[float, float]:
    """Read the recorder's status lines until it reports ``t`` seconds of simulation;
    returns (sim time reached, sim time on disk) from the last line read."""
    assert proc.stderr is not None
    while True:
        line = proc.stderr.readline()
        assert line, f"recorder ended before {t} s (exit {proc.wait()})"
        m = STATUS.search(line)
        if m and float(m.group(1)) >= t:
            return float(m.group(1)), float(m.group(2))


def test_killed_recorder_loses_at_most_the_last_second(tmp_path):
    """kill -9 a recording: the .part holds all it reported on disk, and everything but
    at most the last second of what it had reached (measured by its own status line, not
    the wall clock, so a slow machine changes nothing)."""
    out = tmp_path / "killed.mcap"
    part = tmp_path / "killed.mcap.part"
    proc = _start_recorder(out)
    reached, on_disk = _wait_until_sim_time(proc, 4.0)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert not out.exists() and part.exists()
    warnings: list[str] = []
    log = read_log(part, on_warning=warnings.append)
    assert log.truncated and warnings and "killed.mcap.part" in warnings[0]
    t_last = max(log.poi_t[-1], log.commands[-1].t)
    assert reached - on_disk <= 1.0 + 0.011, (reached, on_disk)  # flushed every second
    # (within one 10 ms tick: a chunk may end between a tick's joint state and its POI)
    assert t_last >= on_disk - 0.011, (t_last, on_disk)
    assert len(log.frames) >= int(10 * (t_last - 0.2))


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_interrupted_recorder_keeps_a_valid_log(tmp_path, sig):
    """Ctrl-C (or SIGTERM) ends the recording cleanly: exit 130, a whole indexed log
    marked interrupted, holding what was recorded up to the signal."""
    out = tmp_path / "stopped.mcap"
    proc = _start_recorder(out)
    reached, _ = _wait_until_sim_time(proc, 4.5)  # after the grasp's mark (about 3 s)
    proc.send_signal(sig)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and f"interrupted ({sig.name})" in stderr
    assert out.exists() and not (tmp_path / "stopped.mcap.part").exists()
    with open(out, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        assert reader.get_summary() is not None
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        t_last = max(m.log_time for _, _, m in reader.iter_messages()) / 1e9
    assert meta["smc_end"]["end"] == "interrupted" and meta["smc_end"]["reason"] == sig.name
    assert t_last >= reached - 1e-9
    log = read_log(out)
    assert not log.truncated and log.poi_t[-1] >= reached - 0.011
    assert log.interrupted and log.end["reason"] == sig.name
    # Compile keeps the complete fragment (the grasp) and says what it dropped.
    warnings: list[str] = []
    result = compile_logs([out], tmp_path / "tree.json", on_warning=warnings.append)
    assert len(result.tree.edges) == 1
    assert any(f"interrupted ({sig.name})" in w and "dropped the last" in w for w in warnings)
