"""Reading logs: ``read_log`` (decoded, checked), ``log_summary`` (counts only), ``strip_topic``.

Reads in file order with mcap's non-seeking ``StreamReader``: a log cut short by a killed
recorder (no summary, torn last chunk) still yields every whole chunk before the cut.
"""

from __future__ import annotations

import bisect
import hashlib
import io
import json
import logging
import os
import struct
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.records import Attachment, Channel, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from smccli.errors import LogError, OutputExistsError
from smccli.logs import topics as tp
from smccli.logs.writer import part_path
from smccli.sensors import CameraFrame, JointState, PoiCommand, SaliencyMark

_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class PointCloudMsg:
    """One message of ``/perception/points``."""

    t: float
    """Simulation time [s]."""
    points: np.ndarray
    """Positions, shape (N, 3) float32 [m], in ``frame_id``."""
    colors: np.ndarray | None
    """RGB colours, shape (N, 3) uint8, or None."""
    frame_id: str


@dataclass(frozen=True, slots=True)
class Scan:
    """One message of ``/lidar/scan``."""

    t: float
    """Simulation time [s]."""
    start_angle: float
    """Bearing of the first range [rad]."""
    end_angle: float
    """Bearing of the last range [rad]."""
    ranges: np.ndarray
    """Ranges, shape (N,) [m]."""
    frame_id: str


@dataclass(frozen=True, slots=True)
class Log:
    """Everything a demonstration or replay log holds, decoded. Times are seconds."""

    path: Path
    sha256: str
    """Hex SHA-256 of the file's bytes (identifies the demo in a compiled tree)."""
    metadata: dict[str, str]
    """The ``smc`` metadata record: scene, scene_digest, smc_version, seed, operator, rates…"""
    attachments: dict[str, bytes]
    """Attachment name -> bytes (the scene's MJCF and YAML)."""
    commands: list[PoiCommand]
    joint_states: list[JointState]
    poi_t: np.ndarray
    """POI times, shape (T,) [s]."""
    poi: np.ndarray
    """POI ``[x, y, z, yaw]``, shape (T, 4) [m, m, m, rad]; yaw unwrapped (continuous)."""
    frames: list[CameraFrame]
    weight_t: np.ndarray
    """Scale times, shape (W,) [s]."""
    weight: np.ndarray
    """Scale readings, shape (W,) [kg]."""
    marks: list[SaliencyMark]
    ground_truth: list[tuple[float, dict[str, np.ndarray]]]
    """(t [s], object name -> pose (7,) ``[x, y, z, qw, qx, qy, qz]``), evaluation only."""
    decisions: list[dict[str, Any]]
    """Replay decisions as written, each with ``"t"`` [s] (its log time) added."""
    topic_counts: dict[str, int]
    """Messages per topic in the file (all topics, decoded or not)."""
    truncated: bool
    """True when the file ends before its footer (killed recorder, ``.part`` file)."""
    point_clouds: list[PointCloudMsg] = field(default_factory=list)
    scans: list[Scan] = field(default_factory=list)


@dataclass(slots=True)
class _Raw:
    """The records of a file in file order, before decoding."""

    header: Header | None = None
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: list[Attachment] = field(default_factory=list)
    messages: list[Message] = field(default_factory=list)
    truncated: bool = False
    cut_at: int = 0

    def topic(self, msg: Message) -> str:
        return self.channels[msg.channel_id].topic


def _read_bytes(path: Path) -> bytes:
    if not path.exists():
        raise LogError(f"{path}: no such file")
    if not path.is_file():
        raise LogError(f"{path}: not a file")
    data = path.read_bytes()
    if not data:
        raise LogError(f"{path}: empty file (0 bytes), expected an MCAP log")
    return data


def _scan(path: Path, data: bytes) -> _Raw:
    raw = _Raw()
    stream = io.BytesIO(data)
    reader = StreamReader(stream, validate_crcs=True)
    footer = False
    try:
        for rec in reader.records:
            if isinstance(rec, Message):
                raw.messages.append(rec)
            elif isinstance(rec, Channel):
                raw.channels[rec.id] = rec
            elif isinstance(rec, Schema):
                raw.schemas[rec.id] = rec
            elif isinstance(rec, Metadata):
                raw.metadata[rec.name] = dict(rec.metadata)
            elif isinstance(rec, Attachment):
                raw.attachments.append(rec)
            elif isinstance(rec, Header):
                raw.header = rec
            elif isinstance(rec, Footer):
                footer = True
    except InvalidMagic:
        if raw.header is None:
            raise LogError(f"{path}: not an MCAP file (bad magic bytes)") from None
        footer = True  # footer read, closing magic damaged: every record is in
    except (EndOfFile, struct.error):
        if raw.header is None:
            raise LogError(f"{path}: not an MCAP file (too short for a header)") from None
    except (McapError, ValueError) as e:  # CRC mismatch, absurd record length, bad zstd
        raise LogError(f"{path}: corrupt MCAP ({e})") from None
    if not footer:
        raw.truncated = True
        raw.cut_at = stream.tell()
    return raw


def _check_times(path: Path, raw: _Raw) -> None:
    last: dict[int, int] = {}
    for m in raw.messages:
        prev = last.get(m.channel_id)
        if prev is not None and m.log_time < prev:
            raise LogError(
                f"{path}: time goes backwards on {raw.topic(m)}: {m.log_time / 1e9:.9f} s "
                f"after {prev / 1e9:.9f} s"
            )
        last[m.channel_id] = m.log_time


def _finite(path: Path, topic: str, t: float, a: Any) -> np.ndarray:
    arr = np.asarray(a, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise LogError(f"{path}: NaN or inf in {topic} at t={t:.3f} s")
    return arr


def read_log(
    path: str | os.PathLike[str],
    *,
    topics: Iterable[str] | None = None,
    required_topics: Iterable[str] = (),
    on_warning: Callable[[str], None] | None = None,
) -> Log:
    """Read and check a log; decode only ``topics`` (all if None).

    Raises LogError (one line naming the file) for a missing file, not MCAP, empty,
    corrupt, a required topic without messages, NaN in poses, time going backwards.
    A truncated log is read up to its last whole chunk and ``on_warning`` is told.
    """
    path = Path(path)
    warn = on_warning or _log.warning
    data = _read_bytes(path)
    raw = _scan(path, data)
    if raw.truncated:
        warn(
            f"{path}: truncated at byte {raw.cut_at} of {len(data)} (recorder killed?); "
            f"read {len(raw.messages)} messages from the whole chunks before the cut"
        )
    _check_times(path, raw)
    counts: dict[str, int] = {c.topic: 0 for c in raw.channels.values()}
    for m in raw.messages:
        counts[raw.topic(m)] += 1
    missing = [t for t in required_topics if counts.get(t, 0) == 0]
    if missing:
        have = ", ".join(sorted(t for t, n in counts.items() if n)) or "none"
        raise LogError(f"{path}: topic {', '.join(missing)} missing (topics present: {have})")
    wanted = None if topics is None else set(topics)
    d = _Decoder(path, raw, wanted, warn)
    for m in raw.messages:
        d.add(m)
    return Log(
        path=path,
        sha256=hashlib.sha256(data).hexdigest(),
        metadata=raw.metadata.get(tp.METADATA_NAME, {}),
        attachments={a.name: a.data for a in raw.attachments},
        commands=d.commands,
        joint_states=d.joint_states,
        poi_t=np.array(d.poi_t, dtype=float),
        poi=_unwrap_yaw(np.array(d.poi, dtype=float).reshape(-1, 4)),
        frames=d.frames(),
        weight_t=np.array(d.weight_t, dtype=float),
        weight=np.array(d.weight, dtype=float),
        marks=d.marks,
        ground_truth=d.ground_truth,
        decisions=d.decisions,
        topic_counts=counts,
        truncated=raw.truncated,
        point_clouds=d.point_clouds,
        scans=d.scans,
    )


def _unwrap_yaw(poi: np.ndarray) -> np.ndarray:
    # The log stores yaw as a quaternion (wrapped to (-pi, pi]); trajectories need it continuous.
    if len(poi):
        poi[:, 3] = np.unwrap(poi[:, 3])
    return poi


class _Decoder:
    """Turns messages into the Log's lists, one topic handler per message kind."""

    def __init__(
        self, path: Path, raw: _Raw, wanted: set[str] | None, warn: Callable[[str], None]
    ) -> None:
        self.path, self.raw, self.wanted, self.warn = path, raw, wanted, warn
        self.commands: list[PoiCommand] = []
        self.joint_states: list[JointState] = []
        self.poi_t: list[float] = []
        self.poi: list[np.ndarray] = []
        self.weight_t: list[float] = []
        self.weight: list[float] = []
        self.marks: list[SaliencyMark] = []
        self.ground_truth: list[tuple[float, dict[str, np.ndarray]]] = []
        self.decisions: list[dict[str, Any]] = []
        self.point_clouds: list[PointCloudMsg] = []
        self.scans: list[Scan] = []
        self.color: list[tuple[int, str, bytes]] = []
        self.depth: dict[tuple[int, str], bytes] = {}
        self.calib: dict[str, list[tuple[int, np.ndarray]]] = {}
        self.tf: dict[str, list[tuple[int, np.ndarray]]] = {}

    def _parse(self, topic: str, m: Message) -> Any:
        ch = self.raw.channels[m.channel_id]
        schema = self.raw.schemas.get(ch.schema_id)
        if topic in tp.JSON_TOPICS:
            if ch.message_encoding != "json":
                raise LogError(f"{self.path}: {topic} is {ch.message_encoding}, expected json")
            try:
                return json.loads(m.data)
            except ValueError as e:
                raise LogError(f"{self.path}: bad JSON on {topic} ({e})") from None
        cls = tp.PROTO_TOPICS[topic]
        name = schema.name if schema else "?"
        if ch.message_encoding != "protobuf" or name != cls.DESCRIPTOR.full_name:
            raise LogError(
                f"{self.path}: {topic} holds {ch.message_encoding} {name}, "
                f"expected protobuf {cls.DESCRIPTOR.full_name}"
            )
        msg = cls()
        msg.ParseFromString(m.data)
        return msg

    def add(self, m: Message) -> None:
        topic = self.raw.topic(m)
        if (self.wanted is not None and topic not in self.wanted) or (
            topic not in tp.JSON_TOPICS and topic not in tp.PROTO_TOPICS
        ):
            return
        msg, t_ns = self._parse(topic, m), m.log_time
        t = t_ns / 1e9
        if topic == tp.COMMAND:
            target = _finite(self.path, topic, t, msg["target"])
            self.commands.append(PoiCommand(t=t, target=target, gripper=float(msg["gripper"])))
        elif topic == tp.JOINT_STATES:
            j = msg.joints
            self.joint_states.append(
                JointState(
                    t=t,
                    names=tuple(x.name for x in j),
                    position=np.array([x.position for x in j]),
                    velocity=np.array([x.velocity for x in j]),
                    effort=np.array([x.effort for x in j]),
                )
            )
        elif topic == tp.POI:
            pos, q = tp.get_pose(msg.pose)
            self.poi_t.append(t)
            self.poi.append(_finite(self.path, topic, t, [*pos, tp.quat_to_yaw(q)]))
        elif topic == tp.COLOR:
            self.color.append((t_ns, msg.frame_id, msg.data))
        elif topic == tp.DEPTH:
            self.depth[(t_ns, msg.frame_id)] = msg.data
        elif topic == tp.CALIBRATION:
            K = np.array(msg.K, dtype=float).reshape(3, 3)
            self.calib.setdefault(msg.frame_id, []).append((t_ns, K))
        elif topic == tp.TF:
            for tr in msg.transforms:
                pos, q = tp.get_pose(tr)
                _finite(self.path, topic, t, [*pos, *q])
                T = np.eye(4)
                T[:3, :3], T[:3, 3] = tp.quat_to_matrix(q), pos
                self.tf.setdefault(tr.child_frame_id, []).append((t_ns, T))
        elif topic == tp.WEIGHT:
            self.weight_t.append(t)
            self.weight.append(float(msg["kg"]))
        elif topic == tp.SALIENCY:
            self.marks.append(SaliencyMark(t=t, source=msg["source"], label=msg.get("label", "")))
        elif topic == tp.GROUND_TRUTH:
            poses = {k: _finite(self.path, topic, t, v) for k, v in msg["poses"].items()}
            self.ground_truth.append((t, poses))
        elif topic == tp.DECISION:
            self.decisions.append({**msg, "t": t})
        elif topic == tp.POINTS:
            self.point_clouds.append(_decode_points(t, msg))
        elif topic == tp.SCAN:
            ranges = np.array(msg.ranges, dtype=float)
            self.scans.append(Scan(t, msg.start_angle, msg.end_angle, ranges, msg.frame_id))

    def frames(self) -> list[CameraFrame]:
        """Colour frames joined with depth (same time), latest calibration and camera pose."""
        want_depth = self.wanted is None or tp.DEPTH in self.wanted
        out, dropped = [], 0
        for t_ns, frame_id, data in self.color:
            K = _latest(self.calib.get(frame_id, []), t_ns)
            T = _latest(self.tf.get(frame_id, []), t_ns)
            rgb = tp.decode_color(data)
            if want_depth:
                dbytes = self.depth.get((t_ns, frame_id))
                depth = tp.decode_depth(dbytes) if dbytes is not None else None
            else:
                depth = np.zeros((0, 0), np.float32)
            if K is None or T is None or rgb is None or depth is None:
                dropped += 1
                continue
            out.append(CameraFrame(t_ns / 1e9, rgb, depth, K, T, frame_id))
        # The last frame of a truncated log may lack its depth or pose: expected, no warning.
        if dropped > (1 if self.raw.truncated else 0):
            self.warn(f"{self.path}: {dropped} camera frames lack depth, calibration or pose")
        return out


def _latest(series: list[tuple[int, np.ndarray]], t_ns: int) -> np.ndarray | None:
    """Value of the last entry at or before ``t_ns`` (series in time order)."""
    i = bisect.bisect_right(series, t_ns, key=lambda e: e[0])
    return series[i - 1][1] if i else None


def _decode_points(t: float, msg: Any) -> PointCloudMsg:
    fields = {f.name: f.offset for f in msg.fields}
    stride = msg.point_stride
    buf = np.frombuffer(msg.data, dtype=np.uint8).reshape(-1, stride)
    pts = np.stack(
        [buf[:, fields[c] : fields[c] + 4].copy().view("<f4")[:, 0] for c in "xyz"], axis=1
    )
    colors = None
    if all(c in fields for c in ("red", "green", "blue")):
        colors = np.stack([buf[:, fields[c]] for c in ("red", "green", "blue")], axis=1)
    return PointCloudMsg(t, pts.astype(np.float32), colors, msg.frame_id)


def log_summary(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Duration, topics with counts and rates, saliency marks and size, without decoding images."""
    path = Path(path)
    data = _read_bytes(path)
    raw = _scan(path, data)
    per: dict[str, list[int]] = {c.topic: [] for c in raw.channels.values()}
    marks = []
    for m in raw.messages:
        topic = raw.topic(m)
        per[topic].append(m.log_time)
        if topic == tp.SALIENCY:
            obj = json.loads(m.data)
            marks.append({"t": m.log_time / 1e9, "source": obj["source"], "label": obj["label"]})
    times = [m.log_time for m in raw.messages]
    start, end = (min(times), max(times)) if times else (0, 0)
    topics = {}
    for topic, ts in sorted(per.items()):
        span = (ts[-1] - ts[0]) / 1e9 if len(ts) > 1 else 0.0
        rate = (len(ts) - 1) / span if span > 0 else 0.0
        topics[topic] = {"count": len(ts), "rate_hz": rate}
    return {
        "path": str(path),
        "size_bytes": len(data),
        "start_s": start / 1e9,
        "end_s": end / 1e9,
        "duration_s": (end - start) / 1e9,
        "truncated": raw.truncated,
        "metadata": raw.metadata.get(tp.METADATA_NAME, {}),
        "attachments": sorted(a.name for a in raw.attachments),
        "topics": topics,
        "marks": marks,
    }


def strip_topic(
    src: str | os.PathLike[str],
    dst: str | os.PathLike[str],
    topic: str,
    *,
    force: bool = False,
) -> Path:
    """Copy ``src`` to ``dst`` without ``topic`` (e.g. ``/sim/ground_truth``); other messages
    keep their bytes, times and order."""
    src, dst = Path(src), Path(dst)
    raw = _scan(src, _read_bytes(src))
    topics = sorted({c.topic for c in raw.channels.values()})
    if topic not in topics:
        raise LogError(f"{src}: no topic {topic} (topics: {', '.join(topics)})")
    if dst.exists() and not force:
        raise OutputExistsError(f"{dst}: exists (use --force to overwrite)")
    part = part_path(dst)
    try:
        with open(part, "wb") as f:
            w = Writer(f, compression=CompressionType.ZSTD)
            w.start(
                profile=raw.header.profile if raw.header else "",
                library=raw.header.library if raw.header else "smc",
            )
            for name, meta in raw.metadata.items():
                w.add_metadata(name, meta)
            for a in raw.attachments:
                w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
            schema_ids: dict[int, int] = {}
            channel_ids: dict[int, int] = {}
            for cid, ch in sorted(raw.channels.items()):
                if ch.topic == topic:
                    continue
                if ch.schema_id and ch.schema_id not in schema_ids:
                    s = raw.schemas[ch.schema_id]
                    schema_ids[ch.schema_id] = w.register_schema(s.name, s.encoding, s.data)
                channel_ids[cid] = w.register_channel(
                    ch.topic, ch.message_encoding, schema_ids.get(ch.schema_id, 0), ch.metadata
                )
            for m in raw.messages:
                if m.channel_id in channel_ids:
                    w.add_message(
                        channel_ids[m.channel_id], m.log_time, m.data, m.publish_time, m.sequence
                    )
            w.finish()
        os.replace(part, dst)
    except BaseException:
        part.unlink(missing_ok=True)
        raise
    return dst
