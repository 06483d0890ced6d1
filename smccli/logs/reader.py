"""Reading logs: ``read_log`` (decoded, checked), ``log_summary`` (counts only), ``strip_topic``.

Reads in file order with mcap's non-seeking ``StreamReader``: a log cut short by a killed
recorder (no summary, torn last chunk) still yields every whole chunk before the cut. The
message indexes that follow each chunk say which channels it holds: a reader asking for
some topics leaves the chunks that hold none of them compressed.
"""

from __future__ import annotations

import bisect
import hashlib
import io
import json
import logging
import math
import os
import struct
import xml.etree.ElementTree as ET
import zlib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, TypeVar

import numpy as np
import yaml
import zstandard
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from google.protobuf.message import DecodeError
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    Channel,
    Chunk,
    Footer,
    Header,
    McapRecord,
    Message,
    MessageIndex,
    Metadata,
    Schema,
)
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer
from zstandard import ZstdError

from smccli.errors import LogError
from smccli.logs import topics as tp
from smccli.outputs import check_output, write_atomic
from smccli.world.sensors import CameraFrame, JointState, PoiCommand, SaliencyMark

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
    base_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """A mobile manipulator's base pose times, shape (B,) [s] (empty otherwise)."""
    base: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """Its base pose ``[x, y, yaw]`` (odometry), shape (B, 3) [m, m, rad]; yaw unwrapped.
    Its ``poi`` is then the end effector in the base's frame."""
    end: dict[str, str] = field(default_factory=dict)
    """The ``smc_end`` metadata record: how the recording ended (``end`` = complete |
    interrupted, ``reason``); empty for a log cut short or written before it existed."""
    camera: CameraFrames | None = None
    """With ``read_log(..., lazy_frames=True)``: the camera frames, each decoded when asked
    for (``frames`` is then empty); None otherwise."""

    @property
    def interrupted(self) -> bool:
        """Whether the recording stopped before its operator finished (signal, repair)."""
        return self.end.get("end") == "interrupted"


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
    skipped: dict[int, int] = field(default_factory=dict)
    """Messages per channel in chunks left compressed (no wanted topic in them)."""
    chunks_read: int = 0
    """Chunks decompressed."""

    def topic(self, msg: Message) -> str:
        """Topic of ``msg``'s channel (``_check_channels`` first: KeyError on an unknown one)."""
        return self.channels[msg.channel_id].topic


class _BadContent(Exception):
    """A message that parses but does not hold what its topic promises; the caller adds the
    file, topic and time to make it a LogError."""


def _read_bytes(path: Path) -> bytes:
    if not path.exists():
        raise LogError(f"{path}: no such file")
    if not path.is_file():
        raise LogError(f"{path}: not a file")
    data = path.read_bytes()
    if not data:
        raise LogError(f"{path}: empty file (0 bytes), expected an MCAP log")
    return data


_RECORD = struct.Struct("<BQ")  # opcode, length
_MESSAGE = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time


def _chunk_records(chunk: Chunk) -> list[McapRecord]:
    """The records of a chunk exactly as mcap's ``breakup_chunk(chunk, validate_crc=True)``
    gives them, parsed ~5x faster (struct over the buffer instead of a read per field, 40 %
    of a read_log): messages here, channels and schemas by mcap. Any chunk this does not
    parse plainly (other compression, bad CRC, a record past the end) goes to mcap, which
    raises what it raises."""
    try:
        records = _plain_chunk_records(chunk)
    except Exception:  # mcap decides, below
        records = None
    return breakup_chunk(chunk, validate_crc=True) if records is None else records


def _plain_chunk_records(chunk: Chunk) -> list[McapRecord] | None:
    if chunk.compression == "zstd":
        data = zstandard.decompress(chunk.data, chunk.uncompressed_size)
    elif chunk.compression == "":
        data = chunk.data
    else:
        return None
    if chunk.uncompressed_crc != 0 and zlib.crc32(data) != chunk.uncompressed_crc:
        return None
    out: list[McapRecord] = []
    pos, size = 0, len(data)
    while pos < size:
        if pos + _RECORD.size > size:
            return None
        opcode, length = _RECORD.unpack_from(data, pos)
        pos += _RECORD.size
        end = pos + length
        if end > size:
            return None
        if opcode == Opcode.MESSAGE:
            if length < _MESSAGE.size:
                return None
            channel_id, sequence, log_time, publish_time = _MESSAGE.unpack_from(data, pos)
            out.append(
                Message(
                    channel_id=channel_id,
                    log_time=log_time,
                    data=data[pos + _MESSAGE.size : end],
                    publish_time=publish_time,
                    sequence=sequence,
                )
            )
        elif opcode in (Opcode.CHANNEL, Opcode.SCHEMA):
            stream = ReadDataStream(io.BytesIO(data[pos:end]))
            out.append((Channel if opcode == Opcode.CHANNEL else Schema).read(stream))
            if stream.count != length:
                return None
        pos = end
    return out


def _scan(path: Path, data: bytes, wanted: set[str] | None = None) -> _Raw:
    """The file's records in file order. With ``wanted`` topics, a chunk is decompressed
    only if it may hold one: its message indexes (the records that follow a chunk) name
    its channels, and a chunk whose channels are all known and all unwanted is counted
    from its indexes and skipped. A chunk without indexes (a torn last chunk, a writer
    that writes none) or with a channel not yet defined is read."""
    raw = _Raw()
    stream = io.BytesIO(data)
    reader = StreamReader(stream, validate_crcs=True, emit_chunks=True)
    footer = False
    pending: list[Any] = []  # [chunk, {channel id: messages}] until its indexes are read

    def settle() -> None:
        if not pending:
            return
        chunk, index = pending
        pending.clear()
        known = bool(index) and all(c in raw.channels for c in index)
        if wanted is not None and known and not {raw.channels[c].topic for c in index} & wanted:
            for c, n in index.items():
                raw.skipped[c] = raw.skipped.get(c, 0) + n
            return
        raw.chunks_read += 1
        for r in _chunk_records(chunk):
            _add_record(raw, r)

    try:
        try:
            for rec in reader.records:
                if isinstance(rec, MessageIndex) and pending:
                    pending[1][rec.channel_id] = len(rec.records)
                    continue
                settle()
                if isinstance(rec, Chunk):
                    pending[:] = [rec, {}]
                    continue
                _add_record(raw, rec)
                footer = footer or isinstance(rec, Footer)
        finally:
            settle()  # the last chunk before the footer or the cut
    except InvalidMagic:
        if raw.header is None:
            raise LogError(f"{path}: not an MCAP file (bad magic bytes)") from None
        footer = True  # footer read, closing magic damaged: every record is in
    except (EndOfFile, struct.error):
        if raw.header is None:
            raise LogError(f"{path}: not an MCAP file (too short for a header)") from None
    except (McapError, ValueError, ZstdError) as e:  # CRC mismatch, absurd length, bad zstd
        raise LogError(f"{path}: corrupt MCAP ({e})") from None
    except OverflowError:  # a record length beyond what a read can ask for (> 2**63)
        raise LogError(f"{path}: corrupt MCAP (record length out of range)") from None
    except RuntimeError as e:  # how lz4.frame reports a corrupt lz4 chunk
        raise LogError(f"{path}: corrupt MCAP (lz4 chunk: {e})") from None
    except MemoryError:  # zstandard allocates what a damaged frame header claims
        raise LogError(
            f"{path}: corrupt MCAP (a zstd chunk claims more data than memory holds)"
        ) from None
    if not footer:
        raw.truncated = True
        raw.cut_at = stream.tell()
    return raw


def _add_record(raw: _Raw, rec: McapRecord) -> None:
    """A record (from a chunk or outside one) into ``raw``."""
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


def _check_channels(path: Path, raw: _Raw) -> None:
    """Every message has a Channel record and every channel's schema a Schema record."""
    for cid, ch in sorted(raw.channels.items()):
        if ch.schema_id and ch.schema_id not in raw.schemas:
            raise LogError(
                f"{path}: channel {cid} ({ch.topic}) refers to schema {ch.schema_id}, "
                "which has no Schema record"
            )
    for m in raw.messages:
        if m.channel_id not in raw.channels:
            raise LogError(
                f"{path}: message at t={m.log_time / 1e9:.3f} s on unknown channel "
                f"{m.channel_id} (no Channel record; known: "
                f"{', '.join(str(c) for c in sorted(raw.channels)) or 'none'})"
            )


def _check_mjcf(data: bytes) -> str | None:
    """What is wrong with a ``scene.xml`` attachment, or None. Syntax only: whether MuJoCo
    accepts the model is for its consumer (``smccli.logs.robot.robot_model_of``) to find out."""
    if not data.strip():
        return "empty (expected the scene's MJCF)"
    try:
        root = ET.fromstring(data)
    except ET.ParseError as e:
        return f"not XML ({e})"
    if root.tag != "mujoco":
        return f"not MJCF (root element <{root.tag}>, expected <mujoco>)"
    return None


def _check_scene_yaml(data: bytes, expected: str = "the scene file") -> str | None:
    """What is wrong with a ``scene.yaml`` (or ``robot.yaml``) attachment, or None (syntax
    and outline only)."""
    if not data.strip():
        return f"empty (expected {expected})"
    try:
        doc = yaml.safe_load(data)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(e, "problem", None) or " ".join(str(e).split())
        return f"not YAML ({problem}{where})"
    if not isinstance(doc, dict):
        return f"not a mapping (found {type(doc).__name__})"
    return None


_ATTACHMENT_CHECKS: dict[str, Callable[[bytes], str | None]] = {
    "scene.xml": _check_mjcf,
    "scene.yaml": _check_scene_yaml,
    "robot.yaml": lambda data: _check_scene_yaml(data, "the robot file"),
}
"""Attachment name -> check; attachments of other names are the user's and not looked at."""


def _check_attachments(path: Path, raw: _Raw) -> None:
    for a in raw.attachments:
        check = _ATTACHMENT_CHECKS.get(a.name)
        problem = check(a.data) if check is not None else None
        if problem is not None:
            raise LogError(f"{path}: attachment {a.name}: {problem}")


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
    try:
        arr = np.asarray(a, dtype=float)
    except OverflowError:  # a JSON integer beyond float range: as good as inf
        arr = np.array(np.inf)
    if not np.isfinite(arr).all():  # the method: np.all's dispatch is most of the cost
        raise LogError(f"{path}: NaN or inf in {topic} at t={t:.3f} s")
    return arr


# --- JSON messages ---------------------------------------------------------------------

_NUMBER = (int, float)  # JSON numbers as json.loads returns them; bool is excluded by `type(x) in`


def _numbers(x: Any, n: int) -> bool:
    return type(x) is list and len(x) == n and all(type(v) in _NUMBER for v in x)


def _command_ok(obj: Any) -> bool:
    """Sufficient (not necessary) for ``teleop_command.schema.json``, at ~1 us a message."""
    if type(obj) is not dict or not 2 <= len(obj) <= 3:
        return False
    if len(obj) == 3 and not _numbers(obj.get("base_target"), 3):
        return False
    g = obj.get("gripper")
    return (
        _numbers(obj.get("target"), 4)
        and isinstance(g, _NUMBER)
        and type(g) is not bool
        and 0 <= g <= 1
    )


def _weight_ok(obj: Any) -> bool:
    """Sufficient for ``weight.schema.json``."""
    return type(obj) is dict and len(obj) == 1 and type(obj.get("kg")) in _NUMBER


# jsonschema costs ~60 us per message: 0.15 s of a 0.55 s read_log for the two 100 Hz JSON
# topics of a 12 s demo, so those get a hand check that accepts what the schema accepts
# in the usual form; only what it does not accept goes to jsonschema (exact verdict and
# message). The 10 Hz and rarer topics go to jsonschema directly.
_FAST_OK: dict[str, Callable[[Any], bool]] = {tp.COMMAND: _command_ok, tp.WEIGHT: _weight_ok}


def _json_type(x: Any) -> str:
    if isinstance(x, bool):
        return "a boolean"
    if isinstance(x, _NUMBER):
        return "a number"
    names = {dict: "an object", list: "an array", str: "a string", type(None): "null"}
    return names.get(type(x), type(x).__name__)


def _schema_problem(topic: str, obj: Any) -> str | None:
    """Why ``obj`` does not match the topic's JSON Schema (one short phrase), or None."""
    fast = _FAST_OK.get(topic)
    if fast is not None and fast(obj):
        return None
    from jsonschema.exceptions import best_match

    err = best_match(tp.json_validator(topic).iter_errors(obj))
    if err is None:
        return None
    where = "/".join(str(p) for p in err.absolute_path)
    at = f" in '{where}'" if where else ""
    inst = err.instance
    if err.validator == "required" and isinstance(inst, dict):
        missing = [k for k in err.validator_value if k not in inst]
        return f"missing field {missing[0]!r}{at}"
    if err.validator == "additionalProperties" and isinstance(inst, dict):
        known = set(err.schema.get("properties", {}))
        extra = sorted(str(k) for k in inst if k not in known)
        return f"unexpected field {extra[0]!r}{at}" if extra else err.message[:120]
    if err.validator == "type":
        what = f"field '{where}'" if where else "message"
        return f"{what} is {_json_type(inst)}, expected {err.validator_value}"
    what = f"field '{where}'" if where else "message"
    return f"{what}: {' '.join(err.message.split())[:120]}"


def _json_message(topic: str, data: bytes) -> Any:
    """Parse and validate one message of a JSON topic; _BadContent says what is wrong."""
    try:
        obj = json.loads(data)
    except ValueError as e:  # JSONDecodeError and UnicodeDecodeError
        raise _BadContent(f"not JSON ({e})") from None
    except RecursionError:
        raise _BadContent("not JSON (nested too deeply)") from None
    problem = _schema_problem(topic, obj)
    if problem is not None:
        raise _BadContent(problem)
    return obj


def _bad(path: Path, topic: str, t_ns: int, problem: str) -> LogError:
    """The one error format for a message: ``demo.mcap: /topic at t=1.230 s: problem``."""
    return LogError(f"{path}: {topic} at t={t_ns / 1e9:.3f} s: {problem}")


def read_log(
    path: str | os.PathLike[str],
    *,
    topics: Iterable[str] | None = None,
    required_topics: Iterable[str] = (),
    on_warning: Callable[[str], None] | None = None,
    lazy_frames: bool = False,
) -> Log:
    """Read and check a log; decode only ``topics`` (all if None), and decompress only
    the chunks that may hold them (:func:`_scan`): a check of a message (its schema, its
    time order) covers the chunks read.

    Raises LogError (one line naming the file; for a message also its topic and time) for
    a missing file, not MCAP, empty, corrupt, no readable message, a message on an unknown
    channel, a required topic without messages, a decoded message that does not hold what
    its topic promises (schema, protobuf, image, point layout, NaN in poses), time going
    backwards, a ``scene.xml`` / ``scene.yaml`` attachment that is not XML / YAML.
    A truncated log is read up to its last whole chunk and ``on_warning`` is told; so is a
    log without the ``smc`` metadata record.

    ``lazy_frames``: for a reader that looks at a few frames (compile), ``Log.camera``
    instead of ``Log.frames``: every image is checked from its header and decoded only when
    asked for (:meth:`_Decoder.camera` says what that check does not see).
    """
    path = Path(path)
    warn = on_warning or _log.warning
    data = _read_bytes(path)
    wanted = None if topics is None else set(topics)
    raw = _scan(path, data, wanted)
    if not raw.messages and not raw.skipped:
        why = (
            f"truncated at byte {raw.cut_at} of {len(data)}, before its first chunk ended"
            if raw.truncated
            else "the log holds no messages"
        )
        raise LogError(f"{path}: no readable message ({why})")
    if raw.truncated:
        warn(
            f"{path}: truncated at byte {raw.cut_at} of {len(data)} (recorder killed?); "
            f"read {len(raw.messages)} messages from the whole chunks before the cut"
        )
    _check_channels(path, raw)
    _check_attachments(path, raw)
    if tp.METADATA_NAME not in raw.metadata:
        warn(
            f"{path}: no {tp.METADATA_NAME!r} metadata record (scene, seed and rates unknown; "
            "not written by smc?)"
        )
    _check_times(path, raw)
    counts: dict[str, int] = {c.topic: 0 for c in raw.channels.values()}
    for m in raw.messages:
        counts[raw.topic(m)] += 1
    for cid, n in raw.skipped.items():  # chunks left compressed: counted by their indexes
        counts[raw.channels[cid].topic] += n
    missing = [t for t in required_topics if counts.get(t, 0) == 0]
    if missing:
        have = ", ".join(sorted(t for t, n in counts.items() if n)) or "none"
        raise LogError(f"{path}: topic {', '.join(missing)} missing (topics present: {have})")
    d = _Decoder(path, raw, wanted, warn)
    for m in raw.messages:
        d.add(m)
    return Log(
        path=path,
        sha256=hashlib.sha256(data).hexdigest(),
        metadata=raw.metadata.get(tp.METADATA_NAME, {}),
        end=raw.metadata.get(tp.END_METADATA_NAME, {}),
        attachments={a.name: a.data for a in raw.attachments},
        commands=d.commands,
        joint_states=d.joint_states,
        poi_t=np.array(d.poi_t, dtype=float),
        poi=_unwrap_yaw(np.array(d.poi, dtype=float).reshape(-1, 4)),
        frames=[] if lazy_frames else d.frames(),
        weight_t=np.array(d.weight_t, dtype=float),
        weight=np.array(d.weight, dtype=float),
        marks=d.marks,
        ground_truth=d.ground_truth,
        decisions=d.decisions,
        topic_counts=counts,
        truncated=raw.truncated,
        point_clouds=d.point_clouds,
        scans=d.scans,
        base_t=np.array(d.base_t, dtype=float),
        base=_unwrap_yaw(np.array(d.base, dtype=float).reshape(-1, 3), column=2),
        camera=d.camera() if lazy_frames else None,
    )


def _unwrap_yaw(poi: np.ndarray, column: int = 3) -> np.ndarray:
    # The log stores yaw as a quaternion (wrapped to (-pi, pi]); trajectories need it continuous.
    if len(poi):
        poi[:, column] = np.unwrap(poi[:, column])
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
        self.base_t: list[float] = []
        self.base: list[np.ndarray] = []
        self.weight_t: list[float] = []
        self.weight: list[float] = []
        self.marks: list[SaliencyMark] = []
        self.ground_truth: list[tuple[float, dict[str, np.ndarray]]] = []
        self.decisions: list[dict[str, Any]] = []
        self.point_clouds: list[PointCloudMsg] = []
        self.scans: list[Scan] = []
        self.color: list[tuple[int, str, str, bytes]] = []
        """(t [ns], frame_id, format, bytes) of each colour image, decoded in ``frames``."""
        self.depth: dict[tuple[int, str], tuple[str, bytes]] = {}
        self.calib: dict[str, list[tuple[int, np.ndarray]]] = {}
        self.tf: dict[str, list[tuple[int, tuple[np.ndarray, np.ndarray]]]] = {}
        """Child frame -> (t [ns], (position (3,), quaternion (4,) wxyz)) in time order."""

    def _parse(self, topic: str, m: Message) -> Any:
        ch = self.raw.channels[m.channel_id]
        if topic in tp.JSON_TOPICS:
            if ch.message_encoding != "json":
                raise LogError(f"{self.path}: {topic} is {ch.message_encoding}, expected json")
            return _json_message(topic, m.data)
        cls = tp.PROTO_TOPICS[topic]
        schema = self.raw.schemas.get(ch.schema_id)
        name = schema.name if schema else "?"
        if ch.message_encoding != "protobuf" or name != cls.DESCRIPTOR.full_name:
            raise LogError(
                f"{self.path}: {topic} holds {ch.message_encoding} {name}, "
                f"expected protobuf {cls.DESCRIPTOR.full_name}"
            )
        msg = cls()
        try:
            msg.ParseFromString(m.data)
        except DecodeError as e:
            raise _BadContent(f"protobuf does not decode ({e})") from None
        return msg

    def add(self, m: Message) -> None:
        topic = self.raw.topic(m)
        if (self.wanted is not None and topic not in self.wanted) or (
            topic not in tp.JSON_TOPICS and topic not in tp.PROTO_TOPICS
        ):
            return
        try:
            self._add(topic, m.log_time, self._parse(topic, m))
        except _BadContent as e:
            raise _bad(self.path, topic, m.log_time, str(e)) from None

    def _add(self, topic: str, t_ns: int, msg: Any) -> None:
        t = t_ns / 1e9
        if topic == tp.COMMAND:
            target = _finite(self.path, topic, t, msg["target"])
            gripper = float(_finite(self.path, topic, t, msg["gripper"]))
            base = msg.get("base_target")
            base = None if base is None else _finite(self.path, topic, t, base)
            self.commands.append(PoiCommand(t=t, target=target, gripper=gripper, base=base))
        elif topic == tp.JOINT_STATES:
            self.joint_states.append(self._joint_state(t, msg))
        elif topic == tp.POI:
            pos, q = tp.get_pose(msg.pose)
            _finite(self.path, topic, t, [*pos, *q])
            _rotation(q, "orientation")
            self.poi_t.append(t)
            self.poi.append(np.array([*pos, tp.quat_to_yaw(q)]))
        elif topic == tp.BASE:
            pos, q = tp.get_pose(msg.pose)
            _finite(self.path, topic, t, [*pos, *q])
            _rotation(q, "orientation")
            self.base_t.append(t)
            self.base.append(np.array([pos[0], pos[1], tp.quat_to_yaw(q)]))
        elif topic == tp.COLOR:
            self.color.append((t_ns, msg.frame_id, msg.format, msg.data))
        elif topic == tp.DEPTH:
            self.depth[(t_ns, msg.frame_id)] = (msg.format, msg.data)
        elif topic == tp.CALIBRATION:
            if len(msg.K) != 9:
                raise _BadContent(f"K holds {len(msg.K)} values, expected 9 (3x3, row-major)")
            K = _finite(self.path, topic, t, msg.K).reshape(3, 3)
            self.calib.setdefault(msg.frame_id, []).append((t_ns, K))
        elif topic == tp.TF:
            for tr in msg.transforms:
                pos, q = tp.get_pose(tr)
                _finite(self.path, topic, t, [*pos, *q])
                _rotation(q, f"rotation of {tr.parent_frame_id} -> {tr.child_frame_id}")
                # The matrix is built for the camera frames that use this pose (``_pose``).
                self.tf.setdefault(tr.child_frame_id, []).append((t_ns, (pos, q)))
        elif topic == tp.WEIGHT:
            self.weight_t.append(t)
            self.weight.append(float(_finite(self.path, topic, t, msg["kg"])))
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

    def _joint_state(self, t: float, msg: Any) -> JointState:
        j = msg.joints
        names = tuple(x.name for x in j)
        if self.joint_states and names != self.joint_states[0].names:
            # Compile indexes every reading by the first one's names (fingers, robot model).
            first = self.joint_states[0].names
            raise _BadContent(
                f"joints ({_names(names)}) differ from the first message's ({_names(first)})"
            )
        position = np.array([x.position for x in j])
        if not np.isfinite(position).all():
            raise _BadContent("NaN or inf in joint positions")
        return JointState(
            t=t,
            names=names,
            position=position,
            velocity=np.array([x.velocity for x in j]),
            effort=np.array([x.effort for x in j]),
        )

    def frames(self) -> list[CameraFrame]:
        """Colour frames joined with depth (same time), latest calibration and camera pose.

        An image that does not decode is a LogError naming its topic and time; a colour
        image without depth, calibration or pose is dropped (with a warning, except the
        last one of a truncated log, whose depth may have been in the lost chunk).
        """
        want_depth = self.wanted is None or tp.DEPTH in self.wanted
        out, dropped = [], 0
        for t_ns, frame_id, fmt, data in self.color:
            K = _latest(self.calib.get(frame_id, []), t_ns)
            pose = _latest(self.tf.get(frame_id, []), t_ns)
            rgb = _decode_color(self.path, t_ns, fmt, data)
            depth: np.ndarray | None = np.zeros((0, 0), np.float32)
            if want_depth:
                stored = self.depth.get((t_ns, frame_id))
                if stored is None:
                    depth = None
                else:
                    depth = _decode_depth(self.path, t_ns, *stored, rgb.shape)
            if K is None or pose is None or depth is None:
                dropped += 1
                continue
            out.append(CameraFrame(t_ns / 1e9, rgb, depth, K, _pose_matrix(*pose), frame_id))
        self._dropped(dropped)
        return out

    def camera(self) -> CameraFrames:
        """The frames :meth:`frames` would give, undecoded: each image is checked from its
        header (a plain JPEG or PNG of the expected kind and size) and decoded only when
        asked for. An image the header check cannot vouch for is decoded here, as
        :meth:`frames` does, so it fails with the same LogError."""
        want_depth = self.wanted is None or tp.DEPTH in self.wanted
        kept, dropped = [], 0
        for t_ns, frame_id, fmt, data in self.color:
            K = _latest(self.calib.get(frame_id, []), t_ns)
            pose = _latest(self.tf.get(frame_id, []), t_ns)
            size = _color_size(data)
            if size is None:
                size = _decode_color(self.path, t_ns, fmt, data).shape[:2]
            stored = self.depth.get((t_ns, frame_id)) if want_depth else None
            if stored is not None and _depth_size(stored[1]) != size:
                _decode_depth(self.path, t_ns, *stored, size)  # its LogError, or it is fine
            if K is None or pose is None or (want_depth and stored is None):
                dropped += 1
                continue
            kept.append(_FrameRecord(t_ns, frame_id, fmt, data, stored, K, pose))
        self._dropped(dropped)
        return CameraFrames(self.path, tuple(kept))

    def _dropped(self, dropped: int) -> None:
        # The last frame of a truncated log may lack its depth or pose: expected, no warning.
        if dropped > (1 if self.raw.truncated else 0):
            self.warn(f"{self.path}: {dropped} camera frames lack depth, calibration or pose")


@dataclass(frozen=True, slots=True)
class _FrameRecord:
    """One camera frame of a log, undecoded."""

    t_ns: int
    frame_id: str
    fmt: str
    data: bytes
    """The colour image as stored."""
    depth: tuple[str, bytes] | None
    """(format, bytes) of the depth image; None when depth was not read."""
    K: np.ndarray
    """Intrinsics, shape (3, 3) [px]."""
    pose: tuple[np.ndarray, np.ndarray]
    """Camera position (3,) [m] and quaternion (4,) wxyz in the world."""


@dataclass(frozen=True, slots=True)
class CameraFrames:
    """A log's camera frames decoded on demand (``read_log(..., lazy_frames=True)``): frame
    ``i`` is ``Log.frames[i]`` of an eager read, decoded only when :meth:`frame` is called."""

    path: Path
    records: tuple[_FrameRecord, ...]

    def __len__(self) -> int:
        return len(self.records)

    @property
    def times(self) -> list[float]:
        """Frame times [s], as ``CameraFrame.t``."""
        return [r.t_ns / 1e9 for r in self.records]

    def frame(self, i: int) -> CameraFrame:
        """Decode frame ``i``; LogError (as :func:`read_log`'s) if its image does not decode."""
        r = self.records[i]
        rgb = _decode_color(self.path, r.t_ns, r.fmt, r.data)
        depth = np.zeros((0, 0), np.float32)
        if r.depth is not None:
            depth = _decode_depth(self.path, r.t_ns, *r.depth, rgb.shape)
        return CameraFrame(r.t_ns / 1e9, rgb, depth, r.K, _pose_matrix(*r.pose), r.frame_id)


def _pose_matrix(pos: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Homogeneous transform (4, 4) of a position (3,) and quaternion (4,) wxyz."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = tp.quat_to_matrix(q), pos
    return T


def _decode_color(path: Path, t_ns: int, fmt: str, data: bytes) -> np.ndarray:
    rgb = tp.decode_color(data)
    if rgb is None:
        raise _bad(path, tp.COLOR, t_ns, f"image does not decode {_image(fmt, data)}")
    return rgb


def _decode_depth(
    path: Path, t_ns: int, fmt: str, data: bytes, shape: tuple[int, ...]
) -> np.ndarray:
    """Depth image [m], shape (H, W) float32, of the colour image of shape ``shape``."""
    shape = shape[:2]
    img = tp.decode_image(data)
    if img is None:
        raise _bad(path, tp.DEPTH, t_ns, f"image does not decode {_image(fmt, data)}")
    if img.ndim != 2 or img.dtype != np.uint16:
        found = f"{img.dtype} {'x'.join(str(n) for n in img.shape)}"
        raise _bad(path, tp.DEPTH, t_ns, f"expected a 16-bit one-channel image, found {found}")
    if img.shape != shape:
        raise _bad(
            path,
            tp.DEPTH,
            t_ns,
            f"depth {img.shape[1]}x{img.shape[0]} differs from the colour image's "
            f"{shape[1]}x{shape[0]}",
        )
    return (img.astype(np.float32) / np.float32(tp.DEPTH_SCALE)).astype(np.float32)


# --- image headers ---------------------------------------------------------------------
# Checking an image from its header costs ~10 us; decoding it ~1 ms (a 320x240 JPEG and
# its 16-bit PNG depth, with the conversions). The checks accept only the plain forms our
# recorder writes, whose size and kind OpenCV reports exactly as the header says; anything
# else is decoded. What they cannot see is damage inside the compressed data (a PNG's
# CRCs do cover it; a JPEG's entropy-coded data has no checksum, and libjpeg decodes most
# such damage with a warning anyway).

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_JPEG_SOF = frozenset({0xC0, 0xC1, 0xC2})  # baseline, extended, progressive Huffman
_JPEG_PLAIN = _JPEG_SOF | {0xE0, 0xDB, 0xC4, 0xDD, 0xFE}  # + APP0 (JFIF), DQT, DHT, DRI, COM


def _jpeg_size(data: bytes) -> tuple[int, int] | None:
    """(H, W) of a plain 8-bit three-component JPEG that ends with its EOI, else None."""
    if len(data) < 4 or data[:2] != b"\xff\xd8" or data[-2:] != b"\xff\xd9":
        return None
    pos, size = 2, None
    while pos + 4 <= len(data) and data[pos] == 0xFF:
        marker = data[pos + 1]
        if marker == 0xDA:  # start of scan: the headers are over
            return size
        if marker not in _JPEG_PLAIN:
            return None
        (n,) = struct.unpack_from(">H", data, pos + 2)
        if marker in _JPEG_SOF:
            if size is not None or n != 17 or pos + 2 + n > len(data):
                return None
            bits, h, w, n_comp = struct.unpack_from(">BHHB", data, pos + 4)
            if bits != 8 or n_comp != 3 or not (h and w):
                return None
            size = (h, w)
        pos += 2 + n
    return None


def _png_header(data: bytes) -> tuple[int, int, int, int] | None:
    """(H, W, bit depth, colour type) of a PNG of only IHDR, IDAT and IEND chunks, each with
    its CRC right and nothing after IEND, else None."""
    if data[:8] != _PNG_MAGIC:
        return None
    view = memoryview(data)
    pos, header, idat = 8, None, False
    while pos + 12 <= len(data):
        n, kind = struct.unpack_from(">I4s", data, pos)
        end = pos + 12 + n
        if (
            end > len(data)
            or zlib.crc32(view[pos + 4 : end - 4]) != struct.unpack_from(">I", data, end - 4)[0]
        ):
            return None
        if kind == b"IHDR":
            if pos != 8 or n != 13:
                return None
            w, h, bits, colour, method, filt, interlace = struct.unpack_from(
                ">IIBBBBB", data, pos + 8
            )
            if method or filt or interlace > 1 or not (h and w):
                return None
            header = (h, w, bits, colour)
        elif kind == b"IEND":
            return header if idat and end == len(data) else None
        elif kind == b"IDAT" and header is not None:
            idat = True
        else:
            return None
        pos = end
    return None


def _color_size(data: bytes) -> tuple[int, int] | None:
    """(H, W) of a colour image that decodes to 8-bit three channels, judged by its header."""
    size = _jpeg_size(data)
    if size is None:
        png = _png_header(data)
        size = png[:2] if png is not None and png[2:] == (8, 2) else None  # 8-bit RGB
    return size


def _depth_size(data: bytes) -> tuple[int, int] | None:
    """(H, W) of a 16-bit one-channel PNG, judged by its header, else None."""
    png = _png_header(data)
    return png[:2] if png is not None and png[2:] == (16, 0) else None


def _names(names: tuple[str, ...], limit: int = 8) -> str:
    shown = ", ".join(names[:limit]) + (", ..." if len(names) > limit else "")
    return f"{len(names)}: {shown}" if names else "none"


def _image(fmt: str, data: bytes) -> str:
    return f"(format {fmt!r}, {len(data)} bytes)"


def _rotation(q: np.ndarray, what: str) -> None:
    """A finite quaternion that is a rotation: of unit norm (we write them normalised;
    1e-3 leaves room for float32 writers). A zero one is an unset field."""
    norm = math.hypot(*q)  # no overflow, unlike np.linalg.norm, for absurd components
    if norm == 0:
        raise _BadContent(f"{what} is the zero quaternion (unset?)")
    if abs(norm - 1) > 1e-3:
        raise _BadContent(f"{what} is not a rotation (quaternion of norm {norm:.6g}, expected 1)")


_V = TypeVar("_V")


def _latest(series: list[tuple[int, _V]], t_ns: int) -> _V | None:
    """Value of the last entry at or before ``t_ns`` (series in time order)."""
    i = bisect.bisect_right(series, t_ns, key=lambda e: e[0])
    return series[i - 1][1] if i else None


_F = PackedElementField


def _kind(t: int) -> str:
    """Name of a PackedElementField type (proto3 enums are open: any int may come)."""
    return _F.NumericType.Name(t) if t in _F.NumericType.values() else f"type {t}"


def _decode_points(t: float, msg: Any) -> PointCloudMsg:
    """A foxglove PointCloud with float32 ``x y z`` and optional uint8 ``red green blue``."""
    stride = msg.point_stride
    if stride == 0:
        raise _BadContent("point_stride is 0")
    if len(msg.data) % stride:
        raise _BadContent(
            f"data holds {len(msg.data)} bytes, not a multiple of point_stride {stride}"
        )
    fields = {f.name: f for f in msg.fields}
    colors_named = all(c in fields for c in ("red", "green", "blue"))
    for name, kind, size in [
        *((c, _F.FLOAT32, 4) for c in "xyz"),
        *((c, _F.UINT8, 1) for c in ("red", "green", "blue") if colors_named),
    ]:
        f = fields.get(name)
        if f is None:
            raise _BadContent(f"no field {name!r} (fields: {', '.join(fields) or 'none'})")
        if f.type != kind:
            raise _BadContent(f"field {name!r} is {_kind(f.type)}, expected {_kind(kind)}")
        if f.offset + size > stride:
            raise _BadContent(
                f"field {name!r} at offset {f.offset} ({size} bytes) lies beyond "
                f"point_stride {stride}"
            )
    buf = np.frombuffer(msg.data, dtype=np.uint8).reshape(-1, stride)
    off = {c: fields[c].offset for c in fields}
    pts = np.stack([buf[:, off[c] : off[c] + 4].copy().view("<f4")[:, 0] for c in "xyz"], axis=1)
    colors = None
    if colors_named:
        colors = np.stack([buf[:, off[c]] for c in ("red", "green", "blue")], axis=1)
    return PointCloudMsg(t, pts.astype(np.float32), colors, msg.frame_id)


def log_summary(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Duration, topics with counts and rates, saliency marks and size, without decoding images."""
    path = Path(path)
    data = _read_bytes(path)
    raw = _scan(path, data)
    _check_channels(path, raw)
    per: dict[str, list[int]] = {c.topic: [] for c in raw.channels.values()}
    marks = []
    for m in raw.messages:
        topic = raw.topic(m)
        per[topic].append(m.log_time)
        if topic == tp.SALIENCY and raw.channels[m.channel_id].message_encoding == "json":
            try:
                obj = _json_message(topic, m.data)
            except _BadContent as e:
                raise _bad(path, topic, m.log_time, str(e)) from None
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


def copy_log(
    raw: _Raw,
    out: IO[bytes],
    *,
    keep: Callable[[Channel], bool] | None = None,
    extra_metadata: Mapping[str, Mapping[str, str]] | None = None,
) -> int:
    """Write ``raw`` as a complete, indexed MCAP (zstd chunks, summary) to ``out``.

    Header profile and library, metadata, attachments, the schemas, the channels ``keep``
    accepts (all by default) and their messages, in file order with their times and
    sequence numbers, then ``extra_metadata`` records. Schemas no channel uses are kept
    too. Returns the messages written.
    """
    w = Writer(out, compression=CompressionType.ZSTD)
    header = raw.header
    w.start(profile=header.profile if header else "", library=header.library if header else "smc")
    for name, meta in raw.metadata.items():
        w.add_metadata(name, meta)
    for a in raw.attachments:
        w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    for cid, ch in sorted(raw.channels.items()):
        if keep is not None and not keep(ch):
            continue
        if ch.schema_id and ch.schema_id not in schema_ids and ch.schema_id in raw.schemas:
            s = raw.schemas[ch.schema_id]
            schema_ids[ch.schema_id] = w.register_schema(s.name, s.encoding, s.data)
        channel_ids[cid] = w.register_channel(
            ch.topic, ch.message_encoding, schema_ids.get(ch.schema_id, 0), ch.metadata
        )
    used = {ch.schema_id for ch in raw.channels.values()}
    for sid, s in sorted(raw.schemas.items()):
        if sid not in used:
            w.register_schema(s.name, s.encoding, s.data)
    n = 0
    for m in raw.messages:
        if m.channel_id in channel_ids:
            w.add_message(channel_ids[m.channel_id], m.log_time, m.data, m.publish_time, m.sequence)
            n += 1
    for extra_name, extra_meta in (extra_metadata or {}).items():
        w.add_metadata(extra_name, dict(extra_meta))
    w.finish()
    return n


def strip_topic(
    src: str | os.PathLike[str],
    dst: str | os.PathLike[str],
    topic: str,
    *,
    force: bool = False,
) -> Path:
    """Copy ``src`` to ``dst`` without ``topic`` (e.g. ``/sim/ground_truth``); other messages
    keep their bytes, times and order. ``dst`` is written atomically."""
    src, dst = Path(src), Path(dst)
    raw = _scan(src, _read_bytes(src))
    _check_channels(src, raw)
    topics = sorted({c.topic for c in raw.channels.values()})
    if topic not in topics:
        raise LogError(f"{src}: no topic {topic} (topics: {', '.join(topics)})")
    check_output(dst, force=force)
    buf = io.BytesIO()
    copy_log(raw, buf, keep=lambda ch: ch.topic != topic)
    write_atomic(dst, buf.getvalue())
    return dst
