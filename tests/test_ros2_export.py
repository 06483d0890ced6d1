"""``smc export --ros2``: a native log as a ROS 2 bag (MCAP, CDR, ros2msg) that gives back,
decoded with nothing but mcap-ros2-support, what the native log holds."""

from __future__ import annotations

import json
import math
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import SAMPLE_LOGS, sha256, smc
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from smccli.errors import LogError, OutputError, OutputExistsError
from smccli.logs import Log, read_log
from smccli.logs import topics as tp
from smccli.logs.ros2_export import EXPORT_METADATA_NAME, ExportSummary, export_ros2
from smccli.logs.ros2_msgs import EXPORT_MAP, EXPORT_TOPICS
from smccli.logs.writer import LogWriter
from smccli.world.sensors import PoiCommand, SaliencyMark

LOGS = {
    "bench_pick": SAMPLE_LOGS / "bench_pick" / "demo.mcap",
    "weigh_sort": SAMPLE_LOGS / "weigh_sort" / "demo_heavy.mcap",  # a scale
    "rooms": SAMPLE_LOGS / "rooms" / "demo2.mcap",  # a lidar
}
T = EXPORT_MAP["topics"]


def _topic(key: str) -> str:
    v = T[key]
    return v if isinstance(v, str) else v["topic"]


@dataclass
class Exported:
    src: Path
    bag: Path
    summary: ExportSummary
    log: Log
    native: dict[str, list[tuple[int, Any]]]
    """Native topic -> (log time, parsed message) in file order."""
    ros: dict[str, list[tuple[int, Any]]]
    """ROS 2 topic -> (log time, decoded message) in file order."""


def _native(path: Path) -> dict[str, list[tuple[int, Any]]]:
    out: dict[str, list[tuple[int, Any]]] = defaultdict(list)
    with open(path, "rb") as f:
        for _, ch, m in make_reader(f).iter_messages(log_time_order=False):
            if ch.topic in tp.JSON_TOPICS:
                out[ch.topic].append((m.log_time, json.loads(m.data)))
            else:
                msg = tp.PROTO_TOPICS[ch.topic]()
                msg.ParseFromString(m.data)
                out[ch.topic].append((m.log_time, msg))
    return out


def _decoded(path: Path) -> dict[str, list[tuple[int, Any]]]:
    out: dict[str, list[tuple[int, Any]]] = defaultdict(list)
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, ch, m, msg in reader.iter_decoded_messages(log_time_order=False):
            out[ch.topic].append((m.log_time, msg))
    return out


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> dict[str, Exported]:
    root = tmp_path_factory.mktemp("ros2")
    out = {}
    for name, src in LOGS.items():
        bag = root / f"{name}.mcap"
        summary = export_ros2(src, bag)
        out[name] = Exported(src, bag, summary, read_log(src), _native(src), _decoded(bag))
    return out


def _ns(stamp: Any) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


@pytest.mark.parametrize("name", list(LOGS))
def test_bag_is_a_ros2_bag(exported, name):
    """Plain mcap (no decoder) sees ros2msg schemas, CDR channels, the source's attachments
    and metadata, and smc_export naming the source."""
    e = exported[name]
    with open(e.bag, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        assert reader.get_header().profile == "ros2"
        assert summary.schemas and summary.channels
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
        types = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        attachments = {a.name: a.data for a in reader.iter_attachments()}
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    expected = {ros: kind for pairs in EXPORT_TOPICS.values() for ros, kind in pairs}
    assert types == {t: expected[t] for t in types}
    assert types == e.summary.types
    assert attachments == e.log.attachments
    assert {"scene.xml", "scene.yaml"} <= set(attachments)
    assert metadata[tp.METADATA_NAME] == e.log.metadata
    assert metadata[EXPORT_METADATA_NAME]["source"] == e.src.name
    assert metadata[EXPORT_METADATA_NAME]["source_sha256"] == sha256(e.src)
    assert e.summary.size_bytes == e.bag.stat().st_size
    assert not e.bag.with_name(e.bag.name + ".part").exists()


@pytest.mark.parametrize("name", list(LOGS))
def test_counts_per_topic(exported, name):
    e = exported[name]
    for native, pairs in EXPORT_TOPICS.items():
        n = e.log.topic_counts.get(native, 0)
        if native == tp.SALIENCY:
            n = sum(m.source == "operator" for m in e.log.marks)
        for ros, _ in pairs:
            assert len(e.ros.get(ros, [])) == n, (native, ros)
            assert e.summary.messages.get(ros, 0) == n
    assert not {"/sim/ground_truth", "/smc/decision"} & set(e.ros)
    assert e.summary.skipped.get(tp.GROUND_TRUTH) == e.log.topic_counts[tp.GROUND_TRUTH]
    # Log and publish times are the native log times, in the native order.
    assert [t for t, _ in e.ros["/joint_states"]] == [t for t, _ in e.native[tp.JOINT_STATES]]


@pytest.mark.parametrize("name", list(LOGS))
def test_commands_joints_poi_tf(exported, name):
    e = exported[name]
    targets, grippers = e.ros[_topic("command")], e.ros[_topic("gripper_command")]
    for cmd, (t1, pose), (t2, g) in zip(e.log.commands, targets, grippers, strict=True):
        assert t1 == t2 == tp.to_ns(cmd.t) == _ns(pose.header.stamp)
        assert pose.header.frame_id == EXPORT_MAP["world_frame"]
        p, q = pose.pose.position, pose.pose.orientation
        assert [p.x, p.y, p.z] == cmd.target[:3].tolist()
        assert (q.x, q.y) == (0.0, 0.0)
        assert math.atan2(2 * q.w * q.z, 1 - 2 * q.z * q.z) == pytest.approx(cmd.target[3])
        assert g.data == cmd.gripper
    for js, (_, msg) in zip(e.log.joint_states, e.ros[_topic("joint_states")], strict=True):
        assert _ns(msg.header.stamp) == tp.to_ns(js.t)
        assert tuple(msg.name) == js.names
        assert msg.position == js.position.tolist()
        assert msg.velocity == js.velocity.tolist()
        assert msg.effort == js.effort.tolist()
    for (_, nat), (_, msg) in zip(e.native[tp.POI], e.ros[_topic("poi")], strict=True):
        assert _ns(msg.header.stamp) == nat.timestamp.ToNanoseconds()
        assert msg.header.frame_id == nat.frame_id
        p, q = msg.pose.position, msg.pose.orientation
        np_, nq = nat.pose.position, nat.pose.orientation
        assert (p.x, p.y, p.z, q.x, q.y, q.z, q.w) == (np_.x, np_.y, np_.z, nq.x, nq.y, nq.z, nq.w)
    for (_, nat), (_, msg) in zip(e.native[tp.TF], e.ros["/tf"], strict=True):
        for a, b in zip(nat.transforms, msg.transforms, strict=True):
            assert (b.header.frame_id, b.child_frame_id) == (a.parent_frame_id, a.child_frame_id)
            assert _ns(b.header.stamp) == a.timestamp.ToNanoseconds()
            tr, ro = b.transform.translation, b.transform.rotation
            assert (tr.x, tr.y, tr.z) == (a.translation.x, a.translation.y, a.translation.z)
            r = a.rotation
            assert (ro.x, ro.y, ro.z, ro.w) == (r.x, r.y, r.z, r.w)


@pytest.mark.parametrize("name", list(LOGS))
def test_camera(exported, name):
    """Colour: the same JPEG bytes; depth: the native millimetres, exactly; K equal."""
    e = exported[name]
    colors = e.ros[_topic("color")]
    for (_, nat), (_, msg) in zip(e.native[tp.COLOR], colors, strict=True):
        assert msg.data == nat.data
        assert msg.format == nat.format == "jpeg"
        assert msg.header.frame_id == nat.frame_id == "camera"
        assert _ns(msg.header.stamp) == nat.timestamp.ToNanoseconds()
    depth = e.ros[_topic("depth")]
    for (_, nat), (_, msg) in zip(e.native[tp.DEPTH], depth, strict=True):
        assert (msg.encoding, msg.is_bigendian, msg.step) == ("16UC1", 0, 2 * msg.width)
        mm = np.frombuffer(msg.data, "<u2").reshape(msg.height, msg.width)
        native_mm = tp.decode_image(nat.data)
        assert native_mm is not None and native_mm.dtype == np.uint16
        np.testing.assert_array_equal(mm, native_mm)
    by_t = {_ns(m.header.stamp): m for _, m in depth}
    assert len(e.log.frames) == len(depth)
    scale = EXPORT_MAP["topics"]["depth"]["scale"]
    for f in e.log.frames:
        msg = by_t[tp.to_ns(f.t)]
        mm = np.frombuffer(msg.data, "<u2").reshape(msg.height, msg.width)
        back = (mm.astype(np.float32) / np.float32(round(1 / scale))).astype(np.float32)
        np.testing.assert_array_equal(back, f.depth)  # as read_log decodes the native PNG
    infos = e.ros[_topic("camera_info")]
    assert len(infos) == len(e.log.frames)
    for f, (_, info) in zip(e.log.frames, infos, strict=True):
        K = np.array(info.k).reshape(3, 3)
        np.testing.assert_array_equal(K, f.K)
        np.testing.assert_array_equal(np.array(info.p).reshape(3, 4), np.hstack([f.K, [[0]] * 3]))
        assert info.r == np.eye(3).ravel().tolist()
        assert (info.distortion_model, info.d) == ("plumb_bob", [0.0] * 5)
        assert (info.height, info.width) == f.rgb.shape[:2]


@pytest.mark.parametrize("name", list(LOGS))
def test_marks_weight_points(exported, name):
    e = exported[name]
    marks = [m for m in e.log.marks if m.source == "operator"]
    got = [(t, msg.data) for t, msg in e.ros.get(_topic("marks"), [])]
    assert got == [(tp.to_ns(m.t), m.label) for m in marks]
    assert marks
    weights = e.ros.get(_topic("weight"), [])
    assert [w.data for _, w in weights] == e.log.weight.tolist()
    assert [t for t, _ in weights] == [tp.to_ns(t) for t in e.log.weight_t]
    clouds = e.ros["/perception/points"]
    for pc, (_, msg) in zip(e.log.point_clouds, clouds, strict=True):
        assert msg.height == 1 and msg.width == len(pc.points)
        names = [f.name for f in msg.fields]
        assert names == ["x", "y", "z", "rgb"] if pc.colors is not None else ["x", "y", "z"]
        assert all(f.datatype == 7 for f in msg.fields)  # FLOAT32
        rec = np.frombuffer(msg.data, dtype="<f4").reshape(msg.width, len(names))
        np.testing.assert_array_equal(rec[:, :3], pc.points)
        if pc.colors is not None:
            rgb = rec[:, 3].copy().view("<u4")
            unpacked = np.stack([(rgb >> 16) & 255, (rgb >> 8) & 255, rgb & 255], axis=1)
            np.testing.assert_array_equal(unpacked, pc.colors)


def test_weights_and_scans_present(exported):
    assert len(exported["weigh_sort"].ros[_topic("weight")]) > 100
    assert _topic("weight") not in exported["bench_pick"].ros
    assert len(exported["rooms"].ros[_topic("lidar")]) == len(exported["rooms"].log.scans) > 100
    assert "/lidar/points" in exported["rooms"].ros


def test_scans(exported):
    e = exported["rooms"]
    for s, (t, msg) in zip(e.log.scans, e.ros[_topic("lidar")], strict=True):
        assert t == _ns(msg.header.stamp) == tp.to_ns(s.t)
        assert msg.header.frame_id == s.frame_id
        f32 = np.float32
        assert (msg.angle_min, msg.angle_max) == (f32(s.start_angle), f32(s.end_angle))
        n = len(s.ranges)
        assert msg.angle_increment == f32((s.end_angle - s.start_angle) / (n - 1))
        assert (msg.range_min, msg.range_max) == (f32(0.05), 8.0)
        assert msg.scan_time == f32(0.1)
        ranges = np.array(msg.ranges, dtype=np.float32)
        np.testing.assert_array_equal(ranges, s.ranges.astype(np.float32))  # inf kept
    lidar_points = e.ros["/lidar/points"]
    assert all(m.header.frame_id == "lidar" and m.point_step == 12 for _, m in lidar_points)


def test_synthetic_log(tmp_path):
    """What the samples lack: a scan with no returns (inf), automatic marks (not exported),
    a cloud without colours, a yaw beyond pi, a decision (not exported)."""
    src, bag = tmp_path / "synthetic.mcap", tmp_path / "bag.mcap"
    ranges = np.array([1.0, np.inf, 2.5, np.inf])
    with LogWriter(src, metadata={"scene": "none"}, wall_clock_flush=False) as w:
        w.write_command(PoiCommand(t=0.5, target=np.array([0.1, 0.2, 0.3, 3.5]), gripper=0.25))
        w.write_scan(0.5, ranges, start_angle=-1.0, end_angle=1.0, frame_id="laser")
        w.write_saliency(SaliencyMark(t=0.6, source="auto", label="contact"))
        w.write_saliency(SaliencyMark(t=0.7, source="operator", label="grasped"))
        w.write_point_cloud(0.7, np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]))
        w.write_json(tp.DECISION, 0.8, {"node": "root"})
    summary = export_ros2(src, bag)
    ros = _decoded(bag)
    assert summary.skipped == {tp.SALIENCY: 1, tp.DECISION: 1}
    assert set(ros) == {
        "/teleop/target",
        "/teleop/gripper",
        "/scan",
        "/saliency",
        "/perception/points",
    }
    assert [m.data for _, m in ros["/saliency"]] == ["grasped"]
    ((_, scan),) = ros["/scan"]
    assert scan.header.frame_id == "laser"
    np.testing.assert_array_equal(np.array(scan.ranges), ranges)
    assert scan.angle_increment == np.float32(2.0 / 3)
    ((_, target),) = ros["/teleop/target"]
    q = target.pose.orientation
    assert [q.z, q.w] == [math.sin(1.75), math.cos(1.75)]
    assert ros["/teleop/gripper"][0][1].data == 0.25
    ((_, cloud),) = ros["/perception/points"]
    assert [f.name for f in cloud.fields] == ["x", "y", "z"]
    assert (cloud.point_step, cloud.row_step, cloud.is_dense) == (12, 24, True)
    np.testing.assert_array_equal(
        np.frombuffer(cloud.data, "<f4").reshape(2, 3), [[1, 2, 3], [4, 5, 6]]
    )
    with open(bag, "rb") as f:
        metadata = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    assert metadata["smc"]["scene"] == "none"
    assert metadata["smc_end"]["end"] == "complete"


def test_refuses_existing_output_and_bad_input(tmp_path):
    src = LOGS["bench_pick"]
    bag = tmp_path / "bag.mcap"
    bag.write_bytes(b"keep")
    with pytest.raises(OutputExistsError, match="exists"):
        export_ros2(src, bag)
    assert bag.read_bytes() == b"keep"
    not_mcap = tmp_path / "notes.mcap"
    not_mcap.write_text("not a log\n")
    with pytest.raises(LogError, match="not an MCAP file"):
        export_ros2(not_mcap, tmp_path / "out.mcap")
    assert set(tmp_path.iterdir()) == {bag, not_mcap}  # no output, no .part
    copy = tmp_path / "copy.mcap"
    copy.write_bytes(src.read_bytes())
    with pytest.raises(OutputError, match="is the log being exported"):
        export_ros2(copy, copy, force=True)
    assert sha256(copy) == sha256(src)


def test_cli(tmp_path):
    bag = tmp_path / "bag.mcap"
    src = LOGS["weigh_sort"]
    r = smc("export", src, "--ros2", "-o", bag)
    assert r.returncode == 0, r.stderr
    assert bag.exists() and bag.stat().st_size > 0
    for topic in ("/joint_states", "/scale/weight", "/camera/depth/image_raw"):
        assert topic in r.stdout
    r = smc("export", src, "--ros2", "-o", bag)
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1 and "exists" in r.stderr
    before = sha256(bag)
    assert smc("export", src, "--ros2", "-o", bag, "--force").returncode == 0
    assert sha256(bag) == before  # deterministic
    bad = tmp_path / "bad.mcap"
    bad.write_text("hello\n")
    r = smc("export", bad, "--ros2", "-o", tmp_path / "x.mcap")
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1 and "not an MCAP" in r.stderr
    assert not (tmp_path / "x.mcap").exists()
