"""``smc doctor``: the real command on healthy, unmarked, truncated, killed and garbage logs,
``--repair``, and the library's checks on logs damaged on purpose."""

from __future__ import annotations

import dataclasses
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO, SAMPLE_LOGS, SMC_ENV, sha256, smc
from foxglove_schemas_protobuf.JointStates_pb2 import JointStates
from mcap.reader import make_reader
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader

from smccli.learn.doctor import diagnose, exit_code, repair
from smccli.logs import log_summary, strip_topic
from smccli.logs import topics as tp
from smccli.logs.records import RawLog, read_bytes, scan_records
from smccli.logs.rewrite import copy_log

DEMO = SAMPLE_LOGS / "pick_place" / "demo1.mcap"
CHECKS = (
    "file",
    "crc",
    "summary",
    "read",
    "metadata",
    "end",
    "attachments",
    "schemas",
    "topics",
    "time order",
    "numbers",
    "saliency",
)


def row(stdout: str, name: str) -> str:
    """The table line of check ``name`` (its first line if the detail wraps)."""
    lines = [ln for ln in stdout.splitlines() if ln.startswith(f"│ {name} ")]
    assert lines, f"no row {name!r} in:\n{stdout}"
    return lines[0]


def assert_complete_copy(out: Path, src: Path) -> None:
    """``out`` is a valid indexed MCAP that plain mcap reads with CRCs checked, holding every
    message ``src`` yields before its cut (same order, topics, times and bytes), its
    attachments and metadata."""
    raw = scan_records(src, read_bytes(src))
    with open(out, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        assert reader.get_summary() is not None
        got = [
            (ch.topic, m.log_time, m.publish_time, m.data)
            for _, ch, m in reader.iter_messages(log_time_order=False)
        ]
        attachments = {a.name for a in reader.iter_attachments()}
        metadata = {m.name for m in reader.iter_metadata()}
    want = [(raw.topic(m), m.log_time, m.publish_time, m.data) for m in raw.messages]
    assert len(got) == sum(t["count"] for t in log_summary(src)["topics"].values())
    assert got == want
    assert attachments == {a.name for a in raw.attachments} >= {"scene.xml", "scene.yaml"}
    # A truncated source gains the end record that says it was cut short.
    end = {tp.END_METADATA_NAME} if raw.truncated else set()
    assert metadata == set(raw.metadata) | end >= {tp.METADATA_NAME}
    with open(out, "rb") as f:  # the streaming pass checks the chunk and data-section CRCs
        assert sum(1 for _ in StreamReader(f, validate_crcs=True).records) > len(got)


# --- the command ---


def test_healthy_sample_log_exits_0_and_lists_every_check():
    proc = smc("doctor", DEMO)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    for name in CHECKS:
        assert " ok " in row(proc.stdout, name)
    assert "2 operator marks" in row(proc.stdout, "saliency")
    assert "2 fragments" in row(proc.stdout, "saliency")


def test_log_without_marks_exits_1(tmp_path):
    unmarked = strip_topic(DEMO, tmp_path / "unmarked.mcap", tp.SALIENCY)
    proc = smc("doctor", unmarked)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "warn" in row(proc.stdout, "saliency")
    assert "no operator marks" in row(proc.stdout, "saliency")


def test_truncated_log_warns_and_repair_keeps_every_whole_chunk(tmp_path):
    # Truncated but readable is a warning (exit 1): compile reads it up to the cut.
    data = DEMO.read_bytes()
    part = tmp_path / "demo1.mcap.part"
    part.write_bytes(data[: len(data) // 2])
    before = sha256(part)
    proc = smc("doctor", part)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    summary = row(proc.stdout, "summary")
    assert "warn" in summary and "truncated" in summary and f"byte {len(data) // 2}" in summary

    out = tmp_path / "repaired.mcap"
    proc = smc("doctor", part, "--repair", out)
    # The repaired file is whole and indexed, and says it was cut short: one warning.
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "repaired" in proc.stdout
    tables = proc.stdout.split("repaired.mcap: ", 1)[1]  # the repaired file's table
    assert "warn" in row(tables, "end") and "repaired by smc doctor" in tables
    assert " ok " in row(tables, "summary")
    assert_complete_copy(out, part)
    assert sha256(part) == before


def test_random_bytes_exit_2_with_one_row(tmp_path, rng):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(rng.integers(0, 256, 4096, dtype=np.uint8).tobytes())
    proc = smc("doctor", junk)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "not an MCAP file" in row(proc.stdout, "file")
    assert [ln for ln in proc.stdout.splitlines() if ln.startswith("│ ")] == [
        row(proc.stdout, "file")
    ]


@pytest.mark.parametrize("case", ["output exists", "output is the log", "two logs"])
def test_repair_refusals_are_one_line_exit_2(tmp_path, case):
    part = tmp_path / "demo.mcap.part"
    part.write_bytes(DEMO.read_bytes()[:300_000])
    out = tmp_path / "out.mcap"
    out.write_bytes(b"keep me")
    args: tuple[str | Path, ...] = {
        "output exists": (part, "--repair", out),
        "output is the log": (part, "--repair", part, "--force"),
        "two logs": (part, DEMO, "--repair", tmp_path / "new.mcap"),
    }[case]
    before = sha256(part)
    proc = smc("doctor", *args)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), proc.stderr
    assert "Traceback" not in proc.stderr
    assert out.read_bytes() == b"keep me" and sha256(part) == before
    assert not (tmp_path / "new.mcap").exists()


def test_killed_recorder_part_is_repaired(tmp_path):
    """A real ``kill -9`` of ``smc record --realtime`` mid-recording, then doctor + repair."""
    log = tmp_path / "X.mcap"
    part = tmp_path / "X.mcap.part"
    script = SAMPLE_LOGS / "weigh_sort" / "demo_light.yaml"
    cmd = [sys.executable, "-m", "smccli.cli", "record", "--scene", "weigh_sort"]
    cmd += ["--script", str(script), "--realtime", "-o", str(log)]
    with open(tmp_path / "record.err", "wb") as err:
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, env=SMC_ENV, cwd=REPO)
        try:
            deadline = time.monotonic() + 120  # a loop guard only, never asserted on
            while time.monotonic() < deadline and proc.poll() is None:
                if part.exists() and part.stat().st_size > 200_000:
                    break
                time.sleep(0.1)
            assert proc.poll() is None, (tmp_path / "record.err").read_text()
            assert part.exists() and part.stat().st_size > 200_000, "recording did not grow"
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    assert not log.exists()
    before = sha256(part)

    proc_d = smc("doctor", part)
    assert "truncated" in row(proc_d.stdout, "summary")
    # A warning at least (truncated); an error exactly when compile refuses it (killed before
    # its first complete fragment, which depends on when the kill came).
    proc_c = smc("compile", part, "-o", tmp_path / "t.json")
    assert proc_d.returncode in (1, 2), proc_d.stdout + proc_d.stderr
    assert (proc_d.returncode == 2) == (proc_c.returncode == 2), proc_d.stdout + proc_c.stderr

    out = tmp_path / "Y.mcap"
    proc_r = smc("doctor", part, "--repair", out)
    # The repaired file is sound: what doctor says of it is what compile says.
    proc_rc = smc("compile", out, "-o", tmp_path / "t2.json")
    assert (proc_r.returncode == 2) == (proc_rc.returncode == 2), proc_r.stdout + proc_rc.stderr
    assert_complete_copy(out, part)
    assert sha256(part) == before


# --- the library, on logs damaged on purpose ---


def _rewrite(tmp_path: Path, change, src: Path = DEMO) -> Path:
    """``src`` with its records changed by ``change(raw)``, written as a valid MCAP."""
    raw = scan_records(src, read_bytes(src))
    change(raw)
    out = tmp_path / "changed.mcap"
    with open(out, "wb") as f:
        copy_log(raw, f)
    return out


def _channel(raw: RawLog, topic: str) -> Channel:
    return next(c for c in raw.channels.values() if c.topic == topic)


def _wrong_encoding(raw: RawLog) -> None:
    ch = _channel(raw, tp.COLOR)
    raw.channels[ch.id] = dataclasses.replace(ch, message_encoding="json")


def _unknown_topic(raw: RawLog) -> None:
    raw.channels[99] = Channel(
        id=99, topic="/my/extra", message_encoding="json", schema_id=0, metadata={}
    )
    raw.messages.append(Message(channel_id=99, sequence=0, log_time=1, publish_time=1, data=b"{}"))


def _nan_joint(raw: RawLog) -> None:
    cid = _channel(raw, tp.JOINT_STATES).id
    i = next(i for i, m in enumerate(raw.messages) if m.channel_id == cid)
    msg = JointStates.FromString(raw.messages[i].data)
    msg.joints[0].position = math.nan
    raw.messages[i] = dataclasses.replace(raw.messages[i], data=msg.SerializeToString())


def _backwards(raw: RawLog) -> None:
    cid = _channel(raw, tp.POI).id
    i, j = [k for k, m in enumerate(raw.messages) if m.channel_id == cid][10:12]
    a, b = raw.messages[i], raw.messages[j]
    raw.messages[i] = dataclasses.replace(a, log_time=b.log_time)
    raw.messages[j] = dataclasses.replace(b, log_time=a.log_time)


def _interrupted(raw: RawLog) -> None:
    raw.metadata[tp.END_METADATA_NAME] = {"end": "interrupted", "reason": "SIGINT"}


def _no_scene_xml(raw: RawLog) -> None:
    raw.attachments = [a for a in raw.attachments if a.name != "scene.xml"]


@pytest.mark.parametrize(
    "change, check, status, needle",
    [
        (
            _wrong_encoding,
            "schemas",
            "error",
            "/camera/color: message encoding json (expected protobuf)",
        ),
        (_unknown_topic, "schemas", "ok", "unknown topics, not read: /my/extra"),
        (_nan_joint, "numbers", "error", "NaN/inf in 1 /robot/joint_states"),
        (_backwards, "time order", "error", "/robot/poi goes back"),
        (_interrupted, "end", "warn", "interrupted by SIGINT"),
        (_no_scene_xml, "attachments", "error", "scene.xml missing"),
    ],
    ids=lambda v: getattr(v, "__name__", None),
)
def test_damage_is_reported_on_its_row(tmp_path, change, check, status, needle):
    d = diagnose(_rewrite(tmp_path, change))
    rows = {c.name: c for c in d.checks}
    assert rows[check].status == status and needle in rows[check].detail, rows[check]
    assert d.status == status  # nothing worse on another row
    assert exit_code([d]) == {"ok": 0, "warn": 1, "error": 2}[status]


def test_missing_scale_topic_is_an_error(tmp_path):
    src = SAMPLE_LOGS / "weigh_sort" / "demo_light.mcap"
    d = diagnose(strip_topic(src, tmp_path / "noscale.mcap", tp.WEIGHT))
    rows = {c.name: c for c in d.checks}
    assert rows["topics"].status == "error" and "/scale/weight missing" in rows["topics"].detail


def test_damaged_chunk_names_the_chunk(tmp_path):
    data = bytearray(DEMO.read_bytes())
    data[len(data) // 3] ^= 0xFF
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    d = diagnose(bad)
    rows = {c.name: c for c in d.checks}
    assert d.status == "error" and rows["read"].status == "error"
    assert rows["crc"].status == "error" and rows["crc"].detail.startswith("chunk ")


def test_missing_file_is_a_diagnosis_not_an_exception(tmp_path):
    d = diagnose(tmp_path / "nope.mcap")
    assert d.status == "error" and [c.name for c in d.checks] == ["file"]


def test_repair_of_a_complete_log_copies_it(tmp_path):
    result = repair(DEMO, tmp_path / "copy.mcap")
    assert not result.truncated
    assert result.messages == len(scan_records(DEMO, read_bytes(DEMO)).messages)
    assert_complete_copy(result.path, DEMO)
    assert diagnose(result.path).status == "ok"
