"""Decoding a log's messages, topic by topic, into a :class:`~smccli.logs.log.Log`'s fields."""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar, TypeVar

import numpy as np
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from google.protobuf.message import DecodeError
from mcap.records import Message

from smccli.errors import LogError
from smccli.logs import topics as tp
from smccli.logs.checks import BadContent, finite, json_message, message_error
from smccli.logs.images import color_size, decode_color, decode_depth, depth_size
from smccli.logs.log import CameraFrames, FrameRecord, PointCloudMsg, Scan
from smccli.logs.records import RawLog
from smccli.world.geometry import quat_yaw, se3
from smccli.world.sensors import CameraFrame, JointState, PoiCommand, SaliencyMark


def unwrap_yaw(poi: np.ndarray, column: int = 3) -> np.ndarray:
    # The log stores yaw as a quaternion (wrapped to (-pi, pi]); trajectories need it continuous.
    if len(poi):
        poi[:, column] = np.unwrap(poi[:, column])
    return poi


class Decoder:
    """Turns messages into the Log's lists, one topic handler per message kind."""

    def __init__(
        self, path: Path, raw: RawLog, wanted: set[str] | None, warn: Callable[[str], None]
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
            return json_message(topic, m.data)
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
            raise BadContent(f"protobuf does not decode ({e})") from None
        return msg

    def add(self, m: Message) -> None:
        topic = self.raw.topic(m)
        if (self.wanted is not None and topic not in self.wanted) or (
            topic not in tp.JSON_TOPICS and topic not in tp.PROTO_TOPICS
        ):
            return
        try:
            self._add(topic, m.log_time, self._parse(topic, m))
        except BadContent as e:
            raise message_error(self.path, topic, m.log_time, str(e)) from None

    def _add(self, topic: str, t_ns: int, msg: Any) -> None:
        if decode := self._DECODERS.get(topic):
            decode(self, t_ns / 1e9, t_ns, msg)

    def _command(self, t: float, t_ns: int, msg: Any) -> None:
        """PoiCommand: target (4,), gripper, optional base target (3,)."""
        target = finite(self.path, tp.COMMAND, t, msg["target"])
        gripper = float(finite(self.path, tp.COMMAND, t, msg["gripper"]))
        base = msg.get("base_target")
        base = None if base is None else finite(self.path, tp.COMMAND, t, base)
        self.commands.append(PoiCommand(t=t, target=target, gripper=gripper, base=base))

    def _joint_states(self, t: float, t_ns: int, msg: Any) -> None:
        """JointState: names, position, velocity, effort (n,), the names of the first message."""
        j = msg.joints
        names = tuple(x.name for x in j)
        if self.joint_states and names != self.joint_states[0].names:
            # Compile indexes every reading by the first one's names (fingers, robot model).
            first = self.joint_states[0].names
            raise BadContent(
                f"joints ({name_list(names)}) differ from the first message's ({name_list(first)})"
            )
        position = np.array([x.position for x in j])
        if not np.isfinite(position).all():
            raise BadContent("NaN or inf in joint positions")
        velocity, effort = np.array([x.velocity for x in j]), np.array([x.effort for x in j])
        self.joint_states.append(JointState(t, names, position, velocity, effort))

    def _checked_pose(
        self, topic: str, t: float, pose: Any, what: str = "orientation"
    ) -> tuple[np.ndarray, np.ndarray]:
        """Position (3,) and quaternion (4,) wxyz of a pose, checked finite and a rotation."""
        pos, q = tp.get_pose(pose)
        finite(self.path, topic, t, [*pos, *q])
        check_rotation(q, what)
        return pos, q

    def _poi(self, t: float, t_ns: int, msg: Any) -> None:
        """POI pose as (x, y, z, yaw) [m, rad], yaw still wrapped (``unwrap_yaw``)."""
        pos, q = self._checked_pose(tp.POI, t, msg.pose)
        self.poi_t.append(t)
        self.poi.append(np.array([*pos, quat_yaw(q)]))

    def _base(self, t: float, t_ns: int, msg: Any) -> None:
        """Base pose as (x, y, yaw) [m, rad], yaw still wrapped (``unwrap_yaw``)."""
        pos, q = self._checked_pose(tp.BASE, t, msg.pose)
        self.base_t.append(t)
        self.base.append(np.array([pos[0], pos[1], quat_yaw(q)]))

    def _color(self, t: float, t_ns: int, msg: Any) -> None:
        self.color.append((t_ns, msg.frame_id, msg.format, msg.data))

    def _depth(self, t: float, t_ns: int, msg: Any) -> None:
        """The depth image undecoded, keyed by (t [ns], frame_id) like its colour image."""
        self.depth[(t_ns, msg.frame_id)] = (msg.format, msg.data)

    def _calibration(self, t: float, t_ns: int, msg: Any) -> None:
        """Intrinsics K (3, 3) per camera frame, in time order."""
        if len(msg.K) != 9:
            raise BadContent(f"K holds {len(msg.K)} values, expected 9 (3x3, row-major)")
        K = finite(self.path, tp.CALIBRATION, t, msg.K).reshape(3, 3)
        self.calib.setdefault(msg.frame_id, []).append((t_ns, K))

    def _tf(self, t: float, t_ns: int, msg: Any) -> None:
        for tr in msg.transforms:
            what = f"rotation of {tr.parent_frame_id} -> {tr.child_frame_id}"
            pos, q = self._checked_pose(tp.TF, t, tr, what)
            # The matrix is built for the camera frames that use this pose (``_pose``).
            self.tf.setdefault(tr.child_frame_id, []).append((t_ns, (pos, q)))

    def _weight(self, t: float, t_ns: int, msg: Any) -> None:
        """Scale reading [kg]."""
        self.weight_t.append(t)
        self.weight.append(float(finite(self.path, tp.WEIGHT, t, msg["kg"])))

    def _saliency(self, t: float, t_ns: int, msg: Any) -> None:
        """SaliencyMark: source and label (empty if absent)."""
        self.marks.append(SaliencyMark(t=t, source=msg["source"], label=msg.get("label", "")))

    def _ground_truth(self, t: float, t_ns: int, msg: Any) -> None:
        """Object name -> pose array, as logged, checked finite."""
        poses = {k: finite(self.path, tp.GROUND_TRUTH, t, v) for k, v in msg["poses"].items()}
        self.ground_truth.append((t, poses))

    def _decision(self, t: float, t_ns: int, msg: Any) -> None:
        """The decision's JSON object, with its time ``t`` [s] added."""
        self.decisions.append({**msg, "t": t})

    def _points(self, t: float, t_ns: int, msg: Any) -> None:
        self.point_clouds.append(decode_points(t, msg))

    def _scan(self, t: float, t_ns: int, msg: Any) -> None:
        """Scan: angles [rad] and ranges (n,) [m]."""
        ranges = np.array(msg.ranges, dtype=float)
        self.scans.append(Scan(t, msg.start_angle, msg.end_angle, ranges, msg.frame_id))

    _DECODERS: ClassVar[dict[str, Callable[[Decoder, float, int, Any], None]]] = {
        tp.COMMAND: _command,
        tp.JOINT_STATES: _joint_states,
        tp.POI: _poi,
        tp.BASE: _base,
        tp.COLOR: _color,
        tp.DEPTH: _depth,
        tp.CALIBRATION: _calibration,
        tp.TF: _tf,
        tp.WEIGHT: _weight,
        tp.SALIENCY: _saliency,
        tp.GROUND_TRUTH: _ground_truth,
        tp.DECISION: _decision,
        tp.POINTS: _points,
        tp.SCAN: _scan,
    }
    """Topic -> decoder(self, t [s], t [ns], message); a topic without one is not stored."""

    def frames(self) -> list[CameraFrame]:
        """Colour frames joined with depth (same time), latest calibration and camera pose.

        An image that does not decode is a LogError naming its topic and time; a colour
        image without depth, calibration or pose is dropped (with a warning, except the
        last one of a truncated log, whose depth may have been in the lost chunk).
        """
        want_depth = self.wanted is None or tp.DEPTH in self.wanted
        out, dropped = [], 0
        for t_ns, frame_id, fmt, data in self.color:
            K = latest(self.calib.get(frame_id, []), t_ns)
            pose = latest(self.tf.get(frame_id, []), t_ns)
            rgb = decode_color(self.path, t_ns, fmt, data)
            depth: np.ndarray | None = np.zeros((0, 0), np.float32)
            if want_depth:
                stored = self.depth.get((t_ns, frame_id))
                if stored is None:
                    depth = None
                else:
                    depth = decode_depth(self.path, t_ns, *stored, rgb.shape)
            if K is None or pose is None or depth is None:
                dropped += 1
                continue
            out.append(CameraFrame(t_ns / 1e9, rgb, depth, K, se3(*pose), frame_id))
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
            K = latest(self.calib.get(frame_id, []), t_ns)
            pose = latest(self.tf.get(frame_id, []), t_ns)
            size = color_size(data)
            if size is None:
                size = decode_color(self.path, t_ns, fmt, data).shape[:2]
            stored = self.depth.get((t_ns, frame_id)) if want_depth else None
            if stored is not None and depth_size(stored[1]) != size:
                decode_depth(self.path, t_ns, *stored, size)  # its LogError, or it is fine
            if K is None or pose is None or (want_depth and stored is None):
                dropped += 1
                continue
            kept.append(FrameRecord(t_ns, frame_id, fmt, data, stored, K, pose))
        self._dropped(dropped)
        return CameraFrames(self.path, tuple(kept))

    def _dropped(self, dropped: int) -> None:
        # The last frame of a truncated log may lack its depth or pose: expected, no warning.
        if dropped > (1 if self.raw.truncated else 0):
            self.warn(f"{self.path}: {dropped} camera frames lack depth, calibration or pose")


def name_list(names: tuple[str, ...], limit: int = 8) -> str:
    shown = ", ".join(names[:limit]) + (", ..." if len(names) > limit else "")
    return f"{len(names)}: {shown}" if names else "none"


def check_rotation(q: np.ndarray, what: str) -> None:
    """A finite quaternion that is a rotation: of unit norm (we write them normalised;
    1e-3 leaves room for float32 writers). A zero one is an unset field."""
    norm = math.hypot(*q)  # no overflow, unlike np.linalg.norm, for absurd components
    if norm == 0:
        raise BadContent(f"{what} is the zero quaternion (unset?)")
    if abs(norm - 1) > 1e-3:
        raise BadContent(f"{what} is not a rotation (quaternion of norm {norm:.6g}, expected 1)")


_V = TypeVar("_V")


def latest(series: list[tuple[int, _V]], t_ns: int) -> _V | None:
    """Value of the last entry at or before ``t_ns`` (series in time order)."""
    i = bisect.bisect_right(series, t_ns, key=lambda e: e[0])
    return series[i - 1][1] if i else None


_F = PackedElementField


def point_kind(t: int) -> str:
    """Name of a PackedElementField type (proto3 enums are open: any int may come)."""
    return _F.NumericType.Name(t) if t in _F.NumericType.values() else f"type {t}"


def decode_points(t: float, msg: Any) -> PointCloudMsg:
    """A foxglove PointCloud with float32 ``x y z`` and optional uint8 ``red green blue``."""
    stride = msg.point_stride
    if stride == 0:
        raise BadContent("point_stride is 0")
    if len(msg.data) % stride:
        raise BadContent(
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
            raise BadContent(f"no field {name!r} (fields: {', '.join(fields) or 'none'})")
        if f.type != kind:
            raise BadContent(f"field {name!r} is {point_kind(f.type)}, expected {point_kind(kind)}")
        if f.offset + size > stride:
            raise BadContent(
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
