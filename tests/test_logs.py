"""Logs: round trips of every topic, MCAP validity, crash safety, Rerun import, error messages."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Chunk
from mcap.writer import CompressionType, Writer
from mcap_protobuf.schema import build_file_descriptor_set

import smccli
from smccli.errors import LogError, OutputExistsError
from smccli.logs import LogWriter, log_summary, part_path, read_log, strip_topic
from smccli.logs import topics as tp
from smccli.world import geometry
from smccli.world.sensors import CameraFrame, JointState, PoiCommand, SaliencyMark

REPO = Path(smccli.__file__).resolve().parent.parent
H, W = 240, 320
K = np.array([[250.0, 0.0, 160.0], [0.0, 250.0, 120.0], [0.0, 0.0, 1.0]])


def _T(yaw: float, p: tuple[float, float, float]) -> np.ndarray:
    """A camera looking down-ish, rotated by yaw about z."""
    c, s = np.cos(yaw), np.sin(yaw)
    Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    Rx = np.array([[1, 0, 0], [0, -0.6, -0.8], [0, 0.8, -0.6]])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = Rz @ Rx, p
    return T


def synthetic_frame(t: float) -> CameraFrame:
    """A smooth, noise-free scene like a simulator's: textured floor, a moving box."""
    v, u = np.mgrid[0:H, 0:W]
    floor = ((u // 20 + v // 20) % 2 * 40 + 90).astype(np.uint8)
    rgb = np.stack([floor, floor, floor + 10], axis=-1)
    depth = (0.8 + 1.2 * v / H).astype(np.float32)
    x0 = int(60 + 100 * np.sin(t))
    rgb[100:150, x0 : x0 + 50] = (200, 30, 30)
    depth[100:150, x0 : x0 + 50] = 0.75
    depth[:5] = np.inf  # nothing hit
    depth[5:10] = 0.0
    return CameraFrame(t=t, rgb=rgb, depth=depth, K=K, T_world_camera=_T(0.3, (0.1, -0.2, 1.1)))


def write_demo(
    path: Path, seconds: float = 2.0, *, camera_hz: int = 10, **kw: object
) -> dict[str, list]:
    """A demo with every topic; returns what was written, per kind."""
    written: dict[str, list] = {
        k: [] for k in ("cmd", "js", "poi", "base", "cam", "gt", "pc", "dec")
    }
    rng = np.random.default_rng(0)
    kw.setdefault("metadata", {"scene": "pick_place", "seed": "0", "operator": "script"})
    kw.setdefault("attachments", {"scene.xml": ("application/xml", b"<mujoco/>")})
    kw.setdefault("wall_clock_flush", False)
    with LogWriter(path, **kw) as w:  # type: ignore[arg-type]
        n = int(seconds * 100)
        for k in range(n):
            t = k / 100
            # Every other command also moves a mobile manipulator's base.
            base = np.array([t / 5, -t / 10, 0.3 * t]) if k % 2 else None
            cmd = PoiCommand(t, np.array([0.4 + t / 10, 0.0, 0.3, 0.2 * t]), 1.0 - k / n, base)
            w.write_command(cmd)
            js = JointState(
                t,
                ("j1", "j2", "finger"),
                rng.normal(size=3),
                rng.normal(size=3),
                rng.normal(size=3),
            )
            w.write_joint_state(js)
            poi = np.array([0.4, 0.1 * t, 0.3, 0.5 * t - 0.4])
            w.write_poi(t, poi)
            w.write_base(t, np.array([t / 5, -t / 10, 2.5 * t]))  # yaw wraps: read unwrapped
            written["base"].append((t, np.array([t / 5, -t / 10, 2.5 * t])))
            written["cmd"].append(cmd)
            written["js"].append(js)
            written["poi"].append((t, poi))
            if k % (100 // camera_hz) == 0:
                frame = synthetic_frame(t)
                w.write_camera(frame)
                w.write_weight(t, 0.25 + t)
                gt = {"cube": np.array([0.5, 0.1, 0.02, 1.0, 0.0, 0.0, 0.0])}
                w.write_ground_truth(t, gt)
                written["cam"].append(frame)
                written["gt"].append((t, gt))
        w.write_saliency(SaliencyMark(0.5, "operator", "grasp"))
        w.write_saliency(SaliencyMark(1.0, "auto", "weight change"))
        pts = rng.uniform(-1, 1, size=(50, 3)).astype(np.float32)
        cols = rng.integers(0, 255, size=(50, 3), dtype=np.uint8)
        w.write_point_cloud(1.0, pts, cols)
        w.write_point_cloud(1.1, pts)
        written["pc"] = [(pts, cols), (pts, None)]
        w.write_scan(1.0, np.linspace(0.5, 2.0, 90), start_angle=-1.0, end_angle=1.0)
        w.write_point_cloud(1.0, pts, frame_id="lidar", topic=tp.SCAN_POINTS)
        dec = {
            "node": 3,
            "candidates": [{"edge": "a", "d_p": 0.1, "d_a": 0.2}],
            "chosen": "a",
            "mapped_goal": [0.5, 0.1, 0.2, 0.0],
            "timings": {"perceive": 0.01},
        }
        w.write_json(tp.DECISION, 1.2, dec)
        written["dec"].append(dec)
    return written


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, list]]:
    path = tmp_path_factory.mktemp("logs") / "demo.mcap"
    return path, write_demo(path)


def test_round_trip_every_topic(demo: tuple[Path, dict[str, list]]) -> None:
    path, wr = demo
    log = read_log(path)
    assert not log.truncated
    assert log.metadata["scene"] == "pick_place"
    assert log.metadata["smc_version"] == smccli.__version__
    assert log.attachments == {"scene.xml": b"<mujoco/>"}
    assert len(log.commands) == len(wr["cmd"])
    for a, b in zip(log.commands, wr["cmd"], strict=True):
        assert a.t == pytest.approx(b.t, abs=1e-9)
        np.testing.assert_array_equal(a.target, b.target)
        assert a.gripper == b.gripper
        assert (a.base is None) == (b.base is None)
        if b.base is not None:
            np.testing.assert_array_equal(a.base, b.base)
    for a, b in zip(log.joint_states, wr["js"], strict=True):
        assert a.names == b.names
        np.testing.assert_array_equal(a.position, b.position)
        np.testing.assert_array_equal(a.velocity, b.velocity)
        np.testing.assert_array_equal(a.effort, b.effort)
    np.testing.assert_allclose(log.poi_t, [t for t, _ in wr["poi"]], atol=1e-9)
    np.testing.assert_allclose(log.poi, [p for _, p in wr["poi"]], atol=1e-12)
    np.testing.assert_allclose(log.base_t, [t for t, _ in wr["base"]], atol=1e-9)
    np.testing.assert_allclose(log.base, [b for _, b in wr["base"]], atol=1e-9)
    assert len(log.frames) == len(wr["cam"])
    for a, b in zip(log.frames, wr["cam"], strict=True):
        assert a.t == pytest.approx(b.t, abs=1e-9)
        # JPEG q90 on a sharp-edged image: small mean error, bounded worst case.
        err = np.abs(a.rgb.astype(int) - b.rgb.astype(int))
        assert a.rgb.shape == b.rgb.shape and err.mean() < 3 and np.percentile(err, 99) < 40
        hit = np.isfinite(b.depth) & (b.depth > 0)
        np.testing.assert_allclose(a.depth[hit], b.depth[hit], atol=0.0005 + 1e-6)  # 1 mm steps
        assert np.all(a.depth[~hit] == 0)
        np.testing.assert_allclose(a.K, b.K)
        np.testing.assert_allclose(a.T_world_camera, b.T_world_camera, atol=1e-12)
    np.testing.assert_allclose(log.weight, [0.25 + f.t for f in wr["cam"]])
    assert [(m.t, m.source, m.label) for m in log.marks] == [
        (0.5, "operator", "grasp"),
        (1.0, "auto", "weight change"),
    ]
    assert len(log.ground_truth) == len(wr["gt"])
    np.testing.assert_array_equal(log.ground_truth[0][1]["cube"], wr["gt"][0][1]["cube"])
    (pts, cols), (_, none) = wr["pc"]
    np.testing.assert_array_equal(log.point_clouds[0].points, pts)
    np.testing.assert_array_equal(log.point_clouds[0].colors, cols)
    assert log.point_clouds[1].colors is None
    np.testing.assert_allclose(log.scans[0].ranges, np.linspace(0.5, 2.0, 90))
    assert log.decisions == [{**wr["dec"][0], "t": 1.2}]
    assert log.topic_counts[tp.COLOR] == len(wr["cam"])
    assert len(log.sha256) == 64


def test_topic_filter_skips_decoding(demo: tuple[Path, dict[str, list]]) -> None:
    path, wr = demo
    log = read_log(path, topics={tp.POI})
    assert len(log.poi) == len(wr["poi"]) and log.frames == [] and log.commands == []
    assert log.topic_counts[tp.COLOR] == len(wr["cam"])  # still counted


def test_file_passes_mcap_crc_checks_and_lists_schemas(demo: tuple[Path, dict[str, list]]) -> None:
    path, _ = demo
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        n = sum(1 for _ in reader.iter_messages())
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert n == summary.statistics.message_count
        schemas = {s.name: s.encoding for s in summary.schemas.values()}
        channels = {c.topic: c.message_encoding for c in summary.channels.values()}
        names = [m.name for m in reader.iter_metadata()]
        atts = [a.name for a in reader.iter_attachments()]
    assert schemas == {
        "foxglove.JointStates": "protobuf",
        "foxglove.PoseInFrame": "protobuf",
        "foxglove.FrameTransforms": "protobuf",
        "foxglove.CompressedImage": "protobuf",
        "foxglove.CameraCalibration": "protobuf",
        "foxglove.PointCloud": "protobuf",
        "foxglove.LaserScan": "protobuf",
        "smc.TeleopCommand": "jsonschema",
        "smc.Weight": "jsonschema",
        "smc.SaliencyMark": "jsonschema",
        "smc.GroundTruth": "jsonschema",
        "smc.Decision": "jsonschema",
    }
    assert set(channels) == set(tp.PROTO_TOPICS) | set(tp.JSON_TOPICS)
    assert all(
        enc == ("json" if t in tp.JSON_TOPICS else "protobuf") for t, enc in channels.items()
    )
    # "smc" at the start; "smc_end" when closed: how the recording ended
    assert names == ["smc", "smc_end"] and atts == ["scene.xml"]


def test_same_inputs_give_identical_bytes(tmp_path: Path) -> None:
    write_demo(tmp_path / "a.mcap", 0.5)
    write_demo(tmp_path / "b.mcap", 0.5)
    assert (tmp_path / "a.mcap").read_bytes() == (tmp_path / "b.mcap").read_bytes()


def test_size_per_second_of_log(tmp_path: Path) -> None:
    """20 s at 100 Hz state and 10 Hz 320x240 colour + depth stays well under 5 MB."""
    path = tmp_path / "long.mcap"
    write_demo(path, 20.0)
    size = path.stat().st_size
    assert size < 5e6, size


def test_existing_output_needs_force(tmp_path: Path) -> None:
    path = tmp_path / "x.mcap"
    path.write_bytes(b"keep")
    with pytest.raises(OutputExistsError, match="x.mcap"):
        LogWriter(path, metadata={})
    assert path.read_bytes() == b"keep" and not part_path(path).exists()
    with LogWriter(path, metadata={}, force=True) as w:
        w.write_weight(0.0, 1.0)
    assert read_log(path).weight.tolist() == [1.0]


def test_abort_and_exception_remove_part(tmp_path: Path) -> None:
    path = tmp_path / "x.mcap"
    w = LogWriter(path, metadata={})
    w.write_weight(0.0, 1.0)
    assert part_path(path).exists()
    w.abort()
    assert not part_path(path).exists() and not path.exists()
    with pytest.raises(RuntimeError), LogWriter(path, metadata={}) as w:
        w.write_weight(0.0, 1.0)
        raise RuntimeError("operator pressed discard")
    assert not part_path(path).exists() and not path.exists()


def test_every_command_written_matches_its_schema(demo: tuple[Path, dict[str, list]]) -> None:
    """write_command checks by hand what the schema asks: the messages it wrote pass the
    schema's own validator (a mobile manipulator's base target included)."""
    path, wr = demo
    validator = tp.json_validator(tp.COMMAND)
    with open(path, "rb") as f:
        messages = [json.loads(m.data) for _, _, m in make_reader(f).iter_messages([tp.COMMAND])]
    assert len(messages) == len(wr["cmd"]) and any("base_target" in m for m in messages)
    for m in messages:
        assert not list(validator.iter_errors(m)), m


def test_writer_refuses_bad_input(tmp_path: Path) -> None:
    with LogWriter(tmp_path / "x.mcap", metadata={}) as w:
        with pytest.raises(ValueError, match="POI"):
            w.write_poi(0.0, np.array([np.nan, 0, 0, 0]))
        with pytest.raises(ValueError, match="schema"):
            w.write_json(tp.DECISION, 0.0, {"candidates": []})  # no node
        with pytest.raises(ValueError, match="unknown topic"):
            w._write("/nope", 0, b"")
        # Commands are checked by hand (not by the validator): what the schema refuses.
        for bad in (
            PoiCommand(0.0, np.array([0.4, 0.0, 0.3]), 1.0),
            PoiCommand(0.0, np.array([0.4, 0.0, 0.3, 0.0]), 1.5),
            PoiCommand(0.0, np.array([0.4, 0.0, 0.3, 0.0]), -0.1),
            PoiCommand(0.0, np.array([0.4, 0.0, 0.3, 0.0]), 1.0, np.array([0.0, 0.0])),
        ):
            with pytest.raises(ValueError, match="/teleop/command: message does not match"):
                w.write_command(bad)
        w.write_weight(1.0, 0.0)
        with pytest.raises(LogError, match="backwards on /scale/weight"):
            w.write_weight(0.5, 0.0)


def test_counts_and_size(tmp_path: Path) -> None:
    path = tmp_path / "x.mcap"
    with LogWriter(path, metadata={}) as w:
        for k in range(3):
            w.write_camera(synthetic_frame(k / 10))
        assert w.counts == {tp.COLOR: 3, tp.DEPTH: 3, tp.CALIBRATION: 3, tp.TF: 3}
        assert w.size_bytes > 0
    assert w.size_bytes == path.stat().st_size


def test_wall_clock_flush_when_log_time_stalls(tmp_path: Path) -> None:
    """An idle operator: log time stops, the buffered chunk still reaches the disk."""
    path = tmp_path / "idle.mcap"
    with LogWriter(path, metadata={}, flush_period_s=0.2) as w:
        for k in range(5):
            w.write_weight(k / 100, 1.0)
        before = w.size_bytes
        # The flush thread wakes every 0.05 s; a busy machine may delay it, so wait for
        # the chunk (not a fixed 0.6 s) with a deadline no scheduler delay reaches.
        deadline = time.monotonic() + 60.0
        while w.size_bytes == before and time.monotonic() < deadline:
            time.sleep(0.05)
        assert w.size_bytes > before
        assert len(read_log(part_path(path), on_warning=lambda m: None).weight) == 5


def test_rotation_round_trip() -> None:
    rng = np.random.default_rng(0)
    qs = rng.normal(size=(200, 4))
    qs = np.vstack([qs, [[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1], [1e-9, 1, 1, 0]]])  # 180 deg
    for q in qs:
        R = geometry.quat_matrix(q)
        np.testing.assert_allclose(geometry.quat_matrix(geometry.matrix_quat(R)), R, atol=1e-9)
    for yaw in np.linspace(-3.1, 3.1, 13):
        assert geometry.quat_yaw(geometry.yaw_quat(yaw)) == pytest.approx(yaw, abs=1e-12)


CHILD = textwrap.dedent(
    """
    import sys, time
    import numpy as np
    from smccli.logs import LogWriter
    from smccli.world.sensors import PoiCommand
    w = LogWriter(sys.argv[1], metadata={"scene": "crash"}, flush_period_s=1.0)
    t0 = time.monotonic()
    k = 0
    while True:
        t = k / 100
        while time.monotonic() - t0 < t:  # real time, like the keyboard operator
            time.sleep(0.002)
        w.write_command(PoiCommand(t, np.array([0.5, 0.0, 0.3, 0.0]), 1.0))
        w.write_poi(t, np.array([0.5, 0.0, 0.3, 0.0]))
        print(k, flush=True)
        k += 1
    """
)


def test_killed_recorder_loses_at_most_one_second(tmp_path: Path) -> None:
    path = tmp_path / "crash.mcap"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(path)], stdout=subprocess.PIPE, text=True, env=env
    )
    assert child.stdout is not None
    last = -1
    deadline = time.monotonic() + 60
    while last < 350 and time.monotonic() < deadline:  # 3.5 s of a 5 s run
        last = int(child.stdout.readline())
    child.send_signal(signal.SIGKILL)
    child.wait()
    assert last >= 350
    assert not path.exists() and part_path(path).exists()
    warnings: list[str] = []
    log = read_log(part_path(path), on_warning=warnings.append)
    assert log.truncated and log.metadata["scene"] == "crash"
    assert len(warnings) == 1 and "crash.mcap.part" in warnings[0] and "truncated" in warnings[0]
    n = len(log.commands)
    assert last + 1 - n <= 105, (last, n)  # ~1 s at 100 Hz, plus scheduling slack
    np.testing.assert_allclose([c.t for c in log.commands], np.arange(n) / 100, atol=1e-9)
    assert len(log.poi) >= n - 1


def test_rerun_importer_understands_the_log(demo: tuple[Path, dict[str, list]]) -> None:
    from rerun.chunk import McapReader

    path, _ = demo
    comps: dict[str, set[str]] = {}
    for chunk in McapReader(path, timeline_type="duration_ns").stream():
        names = chunk.to_record_batch().schema.names
        comps.setdefault(chunk.entity_path, set()).update(names)
    assert {"EncodedImage:blob", "EncodedImage:media_type"} <= comps[tp.COLOR]
    assert {"Points3D:positions", "Points3D:colors"} <= comps[tp.POINTS]
    # Foxglove CompressedImage always becomes EncodedImage; the PNG is 16-bit (mm).
    assert "EncodedImage:blob" in comps[tp.DEPTH]
    assert {"Pinhole:image_from_camera", "Pinhole:resolution"} <= comps[tp.CALIBRATION]
    assert {"Transform3D:translation", "Transform3D:quaternion"} <= comps[tp.TF]
    assert "InstancePoses3D:translations" in comps[tp.POI]


def test_strip_topic_and_summary(demo: tuple[Path, dict[str, list]], tmp_path: Path) -> None:
    path, wr = demo
    dst = strip_topic(path, tmp_path / "no_gt.mcap", tp.GROUND_TRUTH)
    a, b = read_log(path), read_log(dst)
    assert tp.GROUND_TRUTH not in b.topic_counts and b.ground_truth == []
    assert {k: v for k, v in a.topic_counts.items() if k != tp.GROUND_TRUTH} == b.topic_counts
    np.testing.assert_array_equal(a.poi, b.poi)
    assert b.metadata == a.metadata and b.attachments == a.attachments
    with pytest.raises(OutputExistsError):
        strip_topic(path, dst, tp.GROUND_TRUTH)
    with pytest.raises(LogError, match="no topic /nope"):
        strip_topic(path, tmp_path / "z.mcap", "/nope")
    s = log_summary(path)
    assert s["duration_s"] == pytest.approx(1.99)
    assert s["topics"][tp.POI]["count"] == 200
    assert s["topics"][tp.POI]["rate_hz"] == pytest.approx(100)
    assert s["topics"][tp.COLOR]["rate_hz"] == pytest.approx(10)
    assert [m["label"] for m in s["marks"]] == ["grasp", "weight change"]
    assert s["size_bytes"] == path.stat().st_size and not s["truncated"]


# --- errors ---


def _raw_log(path: Path, topic: str, messages: list[tuple[int, bytes]]) -> None:
    """A log written without LogWriter's checks, to hold what it would refuse."""
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        if topic in tp.JSON_TOPICS:
            sid = w.register_schema(
                tp.json_schema_name(topic), "jsonschema", tp.json_schema_bytes(topic)
            )
            cid = w.register_channel(topic, "json", sid)
        else:
            cls = tp.PROTO_TOPICS[topic]
            sid = w.register_schema(
                cls.DESCRIPTOR.full_name,
                "protobuf",
                build_file_descriptor_set(cls).SerializeToString(),
            )
            cid = w.register_channel(topic, "protobuf", sid)
        for t, data in messages:
            w.add_message(cid, log_time=t, data=data, publish_time=t)
        w.finish()


def test_errors_name_the_file_and_problem(tmp_path: Path, demo: tuple[Path, dict]) -> None:
    with pytest.raises(LogError, match=r"nothere.mcap: no such file"):
        read_log(tmp_path / "nothere.mcap")
    (tmp_path / "empty.mcap").write_bytes(b"")
    with pytest.raises(LogError, match=r"empty.mcap: empty file"):
        read_log(tmp_path / "empty.mcap")
    (tmp_path / "junk.mcap").write_bytes(b"this is not an mcap file at all")
    with pytest.raises(LogError, match=r"junk.mcap: not an MCAP file"):
        read_log(tmp_path / "junk.mcap")
    with pytest.raises(LogError, match=r"not a file"):
        read_log(tmp_path)
    path, _ = demo
    with pytest.raises(LogError, match=r"demo.mcap: topic /radar/points missing \(topics present"):
        read_log(path, required_topics=[tp.DEPTH, "/radar/points"])

    from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame

    msg = PoseInFrame(frame_id="world")
    msg.pose.position.x = float("nan")
    msg.pose.orientation.w = 1.0
    _raw_log(tmp_path / "nan.mcap", tp.POI, [(0, msg.SerializeToString())])
    with pytest.raises(LogError, match=r"nan.mcap: NaN or inf in /robot/poi at t=0.000 s"):
        read_log(tmp_path / "nan.mcap")
    back = [(2_000_000_000, b'{"kg":1.0}'), (1_000_000_000, b'{"kg":1.0}')]
    _raw_log(tmp_path / "back.mcap", tp.WEIGHT, back)
    with pytest.raises(LogError, match=r"back.mcap: time goes backwards on /scale/weight"):
        read_log(tmp_path / "back.mcap")


def test_corrupt_chunk_is_an_error(demo: tuple[Path, dict]) -> None:
    path, _ = demo
    data = bytearray(path.read_bytes())
    mid = len(data) // 2
    data[mid : mid + 64] = bytes(64)
    bad = path.with_name("corrupt.mcap")
    bad.write_bytes(bytes(data))
    with pytest.raises(LogError, match="corrupt.mcap"):
        read_log(bad, on_warning=lambda m: None)


def test_cut_file_reads_whole_chunks(demo: tuple[Path, dict], tmp_path: Path) -> None:
    path, wr = demo
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    warnings: list[str] = []
    log = read_log(cut, on_warning=warnings.append)
    assert log.truncated and warnings and "cut.mcap" in warnings[0]
    assert 0 < len(log.commands) < len(wr["cmd"])
    assert json.dumps(log_summary(cut)["truncated"]) == "true"


def _one_message_per_chunk(src: Path, out: Path) -> Path:
    """``src`` rewritten by mcap's own writer with every message in a chunk of its own (as
    a writer that chunks per topic would), so the ground truth is in chunks of its own."""
    with open(src, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        metadata = list(reader.iter_metadata())
        attachments = list(reader.iter_attachments())
        messages = list(reader.iter_messages(log_time_order=False))
    with open(out, "wb") as f:
        w = Writer(f, chunk_size=1)
        w.start()
        for s in summary.schemas.values():
            w.register_schema(s.name, s.encoding, s.data)
        for c in summary.channels.values():
            w.register_channel(c.topic, c.message_encoding, c.schema_id, c.metadata)
        for m in metadata:
            w.add_metadata(m.name, m.metadata)
        for a in attachments:
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        for _, channel, msg in messages:
            w.add_message(channel.id, msg.log_time, msg.data, msg.publish_time, msg.sequence)
        w.finish()
    return out


def _rechunked(src: Path, out: Path, compression: CompressionType) -> Path:
    """``src`` rewritten by mcap's own writer with chunks in ``compression``."""
    with open(src, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        messages = list(reader.iter_messages(log_time_order=False))
    with open(out, "wb") as f:
        w = Writer(f, compression=compression, chunk_size=64 * 1024)
        w.start()
        for s in summary.schemas.values():
            w.register_schema(s.name, s.encoding, s.data)
        for c in summary.channels.values():
            w.register_channel(c.topic, c.message_encoding, c.schema_id, c.metadata)
        for _, channel, msg in messages:
            w.add_message(channel.id, msg.log_time, msg.data, msg.publish_time, msg.sequence)
        w.finish()
    return out


def test_the_chunk_walker_reads_what_mcaps_reader_reads(tmp_path: Path) -> None:
    """smc's chunk walker (``records._chunk_records``) builds mcap's record classes: run
    against the installed mcap (pinned in pyproject.toml), it gives every record of every
    chunk as mcap's own StreamReader does, in zstd (smc's logs), lz4 and uncompressed."""
    from mcap.stream_reader import StreamReader

    import smccli.logs.records as records

    src = REPO / "sample_logs" / "bench_pick" / "demo.mcap"
    logs = [src, *(REPO / "sample_logs" / "pick_place").glob("*.mcap")]
    logs += [
        _rechunked(src, tmp_path / f"{c.name}.mcap", c)
        for c in (CompressionType.LZ4, CompressionType.NONE)
    ]
    for log in logs:
        with open(log, "rb") as f:
            theirs = list(StreamReader(f, validate_crcs=True).records)
        with open(log, "rb") as f:
            ours = [
                r
                for rec in StreamReader(f, validate_crcs=True, emit_chunks=True).records
                for r in (records._chunk_records(rec) if isinstance(rec, Chunk) else [rec])
            ]
        assert len(ours) == len(theirs) > 100, log
        assert ours == theirs, log


def test_a_reader_of_some_topics_leaves_the_other_chunks_compressed(tmp_path, monkeypatch):
    """compile reads the topics it needs (``READ_TOPICS``): a chunk holding only ground truth
    is never decompressed, yet counted (its message indexes say how many it holds); what is
    read is what reading every chunk gives."""
    import smccli.logs.records as records
    from smccli.logs.topics import READ_TOPICS

    log = _one_message_per_chunk(
        REPO / "sample_logs" / "bench_pick" / "demo.mcap", tmp_path / "split.mcap"
    )
    with open(log, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    topic_of = {c.id: c.topic for c in summary.channels.values()}
    read: list[set[str]] = []
    plain = records._chunk_records

    def counted(chunk):
        out = plain(chunk)
        read.append({topic_of[r.channel_id] for r in out if hasattr(r, "channel_id")})
        return out

    monkeypatch.setattr(records, "_chunk_records", counted)
    some = read_log(log, topics=READ_TOPICS, lazy_frames=True)
    assert read and not [t for t in read if t <= {tp.GROUND_TRUTH}]
    ground_truth_chunks = some.topic_counts[tp.GROUND_TRUTH]
    assert ground_truth_chunks > 50 and some.ground_truth == []
    read.clear()
    every = read_log(log)
    assert len(read) >= ground_truth_chunks + 50 and len(every.ground_truth) == ground_truth_chunks
    assert some.topic_counts == every.topic_counts
    np.testing.assert_array_equal(some.poi, every.poi)
    assert [c.target.tolist() for c in some.commands] == [c.target.tolist() for c in every.commands]
    assert len(some.camera) == len(every.frames) and some.marks == every.marks
