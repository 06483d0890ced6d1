"""``smc export --ros2``: a native smc log as a ROS 2 bag (MCAP storage, CDR messages).

Each native topic becomes the ROS 2 topics and types of ``ros2_msgs.EXPORT_TOPICS``, with the
``ros2msg`` schemas of ``ros2_msgs.msgdef``; ``ros2_msgs.EXPORT_MAP`` is the topic map that
reads the bag back. What changes on the way:

* ``/teleop/command`` (target ``[x, y, z, yaw]``, gripper) becomes ``/teleop/target``
  (PoseStamped in ``world``, the yaw as a rotation about z) and ``/teleop/gripper``
  (Float64), both stamped with the command's time. A mobile base's ``base_target`` has no
  ROS 2 topic and is not exported.
* ``/camera/color`` keeps its compressed bytes (JPEG, or PNG for a lossless log) and format.
* ``/camera/depth`` (16-bit PNG in millimetres) becomes a raw ``16UC1`` Image of the same
  values, little-endian: lossless (read back with scale 0.001 it is the native depth).
* ``/camera/calibration`` becomes CameraInfo: ``k`` = K, ``p`` = [K | 0], ``r`` = identity,
  ``plumb_bob`` with 5 zero coefficients (the simulated camera has no distortion).
* ``/lidar/scan`` becomes LaserScan (range_min 0.05 m, range_max ``lidar.RANGE_MAX``, scan
  time 0.1 s); the scan's pose in its frame (identity as smc writes it) has no field there.
* ``/lidar/points`` and ``/perception/points`` become PointCloud2 (``x y z`` float32, and
  ``rgb`` packed in a float32 as PCL does when the cloud has colours).
* ``/saliency``: only the operator's marks are exported (String = the label); automatic
  marks (source ``auto``) are not.
* Not exported: ``/sim/ground_truth`` (evaluation only), ``/smc/decision`` and topics smc
  does not know.

Header stamps are the native messages' own times (each transform's for ``/tf``); log and
publish times are the native log times. The bag carries the source's attachments
(``scene.yaml``, ``scene.xml``, ``robot.yaml``) and metadata records (``smc``, ``smc_end``),
plus ``smc_export`` naming the source log and its SHA-256, so it is self-contained.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mcap.records import Message, Schema
from mcap_ros2.writer import Writer as Ros2Writer

from smccli import __version__
from smccli.errors import LogError, OutputError, OutputExistsError
from smccli.logs import topics as tp
from smccli.logs.checks import BadContent
from smccli.logs.decode import decode_points
from smccli.logs.reader import read_log
from smccli.logs.records import read_bytes, scan_records
from smccli.logs.ros2_msgs import EXPORT_TOPICS, export_map, msgdef
from smccli.logs.writer import part_path
from smccli.outputs import check_output
from smccli.world.lidar import RANGE_MAX

EXPORT_METADATA_NAME = "smc_export"
"""Metadata record naming the source of an exported bag: ``source``, ``source_sha256``."""
RANGE_MIN = 0.05
"""LaserScan ``range_min`` [m]."""
SCAN_TIME = 0.1
"""LaserScan ``scan_time`` [s]: the lidar's period."""

_FLOAT32 = 7  # sensor_msgs/PointField.FLOAT32


@dataclass(frozen=True, slots=True)
class ExportSummary:
    """What ``export_ros2`` wrote."""

    out: Path
    messages: dict[str, int]
    """ROS 2 topic -> messages written, in ``EXPORT_TOPICS`` order."""
    types: dict[str, str]
    """ROS 2 topic -> its type (``pkg/msg/Type``)."""
    size_bytes: int
    """Size of the bag."""
    source_bytes: int
    """Size of the native log."""
    skipped: dict[str, int] = field(default_factory=dict)
    """Native topic -> messages not exported (ground truth, decisions, automatic marks…)."""
    scene: str = ""
    """The scene the log was recorded in (its ``smc`` metadata)."""

    def topic_map(self) -> dict[str, object]:
        """The topic map that reads this bag back (``schemas/topic_map.schema.json``)."""
        return export_map(self.scene, self.messages)


def _time(ns: int) -> dict[str, int]:
    """builtin_interfaces/Time of a time in nanoseconds."""
    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return {"sec": sec, "nanosec": nanosec}


def _header(ns: int, frame_id: str) -> dict[str, Any]:
    return {"stamp": _time(ns), "frame_id": frame_id}


def _stamp_ns(msg: Any, default: int) -> int:
    """A foxglove message's own time, or ``default`` (the log time) when it has none."""
    return int(msg.timestamp.ToNanoseconds()) if msg.HasField("timestamp") else default


def _pose(position: Any, orientation: Any) -> dict[str, Any]:
    """geometry_msgs/Pose of a foxglove Vector3/Quaternion pair (fields named alike)."""
    p, o = position, orientation
    return {
        "position": {"x": p.x, "y": p.y, "z": p.z},
        "orientation": {"x": o.x, "y": o.y, "z": o.z, "w": o.w},
    }


def _yaw_pose(target: list[float]) -> dict[str, Any]:
    """Pose of a command target ``[x, y, z, yaw]``: the yaw as a rotation about z."""
    x, y, z, yaw = (float(v) for v in target)
    half = yaw / 2
    return {
        "position": {"x": x, "y": y, "z": z},
        "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(half), "w": math.cos(half)},
    }


def _point_cloud(t_ns: int, msg: Any) -> dict[str, Any]:
    """sensor_msgs/PointCloud2 of a foxglove PointCloud (via the reader's layout checks)."""
    pc = decode_points(t_ns / 1e9, msg)
    n = len(pc.points)
    names = ["x", "y", "z"]
    if pc.colors is None:
        data = np.ascontiguousarray(pc.points, dtype="<f4").tobytes()
    else:
        rec = np.zeros(n, dtype=[("p", "<f4", 3), ("rgb", "<u4")])
        rec["p"] = pc.points
        c = pc.colors.astype(np.uint32)
        rec["rgb"] = (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]  # read as float32: PCL's rgb
        data = rec.tobytes()
        names.append("rgb")
    step = 4 * len(names)
    return {
        "header": _header(_stamp_ns(msg, t_ns), pc.frame_id),
        "height": 1,
        "width": n,
        "fields": [
            {"name": c, "offset": 4 * i, "datatype": _FLOAT32, "count": 1}
            for i, c in enumerate(names)
        ],
        "is_bigendian": False,
        "point_step": step,
        "row_step": step * n,
        "data": data,
        "is_dense": bool(np.isfinite(pc.points).all()),
    }


class _Converter:
    """Native message -> ``[(ROS 2 topic, message dict)]``, one method per native topic."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def convert(self, topic: str, t_ns: int, data: bytes) -> list[tuple[str, dict[str, Any]]]:
        if topic in tp.JSON_TOPICS:
            msg: Any = json.loads(data)
        else:
            msg = tp.PROTO_TOPICS[topic]()
            msg.ParseFromString(data)
        msgs = getattr(self, _METHODS[topic])(t_ns, msg)
        return list(zip(_ROS_TOPIC[topic], msgs, strict=True)) if msgs else []

    def command(self, t_ns: int, msg: Any) -> list[dict[str, Any]]:
        pose = {"header": _header(t_ns, tp.WORLD), "pose": _yaw_pose(msg["target"])}
        return [pose, {"data": float(msg["gripper"])}]

    def joint_states(self, t_ns: int, msg: Any) -> list[dict[str, Any]]:
        j = msg.joints
        return [
            {
                "header": _header(_stamp_ns(msg, t_ns), ""),
                "name": [x.name for x in j],
                "position": [x.position for x in j],
                "velocity": [x.velocity for x in j],
                "effort": [x.effort for x in j],
            }
        ]

    def poi(self, t_ns: int, msg: Any) -> list[dict[str, Any]]:
        p = msg.pose
        header = _header(_stamp_ns(msg, t_ns), msg.frame_id or tp.WORLD)
        return [{"header": header, "pose": _pose(p.position, p.orientation)}]

    def color(self, t_ns: int, msg: Any) -> list[dict[str, Any]]:
        header = _header(_stamp_ns(msg, t_ns), msg.frame_id)
        return [{"header": header, "format": msg.format, "data": bytes(msg.data)}]

    def depth(self, t_ns: int, msg: Any) -> list[dict[str, Any]]:
        img = tp.decode_image(msg.data)
        if img is None or img.ndim != 2 or img.dtype != np.uint16:
            found = "bytes that do not decode" if img is None else f"{img.dtype} {img.shape}"
            raise LogError(
                f"{self.path}: {tp.DEPTH} at t={t_ns / 1e9:.3f} s: expected a 16-bit "
                f"one-channel PNG, found {found}"
            )
        h, w = img.shape
        return [
            {
                "header": _header(_stamp_ns(msg, t_ns), msg.frame_id),
                "height": h,
                "width": w,
                "encoding": "16UC1",
                "is_bigendian": 0,
                "step": 2 * w,
                "data": np.ascontiguousarray(img, dtype="<u2").tobytes(),
            }
        ]

    def calibration(self, t_ns: int, msg: Any) -> list[dict[str, Any]]:
        K = np.asarray(msg.K, dtype=float).reshape(3, 3)
        P = np.zeros((3, 4))
        P[:, :3] = K
        return [
            {
                "header": _header(_stamp_ns(msg, t_ns), msg.frame_id),
                "height": msg.height,
                "width": msg.width,
                "distortion_model": "plumb_bob",
                "d": [0.0] * 5,
                "k": K.ravel().tolist(),
                "r": np.eye(3).ravel().tolist(),
                "p": P.ravel().tolist(),
                "binning_x": 0,
                "binning_y": 0,
                "roi": {},
            }
        ]

    def tf(self, t_ns: int, msg: Any) -> list[dict[str, Any]]:
        transforms = [
            {
                "header": _header(_stamp_ns(tr, t_ns), tr.parent_frame_id),
                "child_frame_id": tr.child_frame_id,
                "transform": {
                    "translation": {"x": tr.translation.x, "y": tr.translation.y,
                                    "z": tr.translation.z},
                    "rotation": {"x": tr.rotation.x, "y": tr.rotation.y, "z": tr.rotation.z,
                                 "w": tr.rotation.w},
                },
            }
            for tr in msg.transforms
        ]  # fmt: skip
        return [{"transforms": transforms}]

    def weight(self, t_ns: int, msg: Any) -> list[dict[str, Any]]:
        return [{"data": float(msg["kg"])}]

    def saliency(self, t_ns: int, msg: Any) -> list[dict[str, Any]]:
        return [{"data": str(msg.get("label", ""))}] if msg["source"] == "operator" else []

    def scan(self, t_ns: int, msg: Any) -> list[dict[str, Any]]:
        n = len(msg.ranges)
        inc = (msg.end_angle - msg.start_angle) / (n - 1) if n > 1 else 0.0
        return [
            {
                "header": _header(_stamp_ns(msg, t_ns), msg.frame_id),
                "angle_min": msg.start_angle,
                "angle_max": msg.end_angle,
                "angle_increment": inc,
                "time_increment": 0.0,
                "scan_time": SCAN_TIME,
                "range_min": RANGE_MIN,
                "range_max": RANGE_MAX,
                "ranges": list(msg.ranges),
                "intensities": list(msg.intensities),
            }
        ]

    def points(self, t_ns: int, msg: Any) -> list[dict[str, Any]]:
        try:
            return [_point_cloud(t_ns, msg)]
        except BadContent as e:
            raise LogError(f"{self.path}: point cloud at t={t_ns / 1e9:.3f} s: {e}") from None


_METHODS: dict[str, str] = {
    tp.COMMAND: "command",
    tp.JOINT_STATES: "joint_states",
    tp.POI: "poi",
    tp.COLOR: "color",
    tp.DEPTH: "depth",
    tp.CALIBRATION: "calibration",
    tp.TF: "tf",
    tp.WEIGHT: "weight",
    tp.SALIENCY: "saliency",
    tp.SCAN: "scan",
    tp.SCAN_POINTS: "points",
    tp.POINTS: "points",
}
"""Native topic -> the ``_Converter`` method that converts its messages."""

_ROS_TOPIC: dict[str, tuple[str, ...]] = {
    native: tuple(topic for topic, _ in ros) for native, ros in EXPORT_TOPICS.items()
}

assert set(_METHODS) == set(EXPORT_TOPICS), "every exported topic needs a converter"


def _check_paths(log: Path, out: Path, part: Path, force: bool) -> None:
    check_output(out, force=force)
    if log.exists() and out.exists() and out.samefile(log):
        raise OutputError(f"{out}: is the log being exported; choose another output")
    if part.exists() and not force:
        raise OutputExistsError(
            f"{part}: exists (a file being written, or left by a killed export or "
            "recording; use --force to overwrite)"
        )


def export_ros2(
    log: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    force: bool = False,
    on_warning: Callable[[str], None] | None = None,
) -> ExportSummary:
    """Write the native smc log ``log`` as a ROS 2 bag ``out`` (MCAP, CDR, ``ros2msg``).

    The output is checked before any work (OutputExistsError when it exists and not
    ``force``; OutputError when it cannot be written or is ``log`` itself), the log is read
    and checked as ``read_log`` does (LogError), and the bag is written to ``OUT.part``,
    synced and renamed, so ``out`` is never half-written. ``on_warning`` hears about a
    truncated log (its whole chunks are exported).
    """
    log, out = Path(log), Path(out)
    part = part_path(out)
    _check_paths(log, out, part, force)
    checked = read_log(log, on_warning=on_warning)  # the whole check: LogError, one line
    data = read_bytes(log)
    raw = scan_records(log, data)

    types = {ros: kind for ros_topics in EXPORT_TOPICS.values() for ros, kind in ros_topics}
    counts: dict[str, int] = {}
    skipped: dict[str, int] = {}
    convert = _Converter(log)
    try:
        with open(part, "wb") as f:
            writer = Ros2Writer(f)
            header = raw.header
            for name, meta in raw.metadata.items():
                writer.add_metadata(name, dict(meta))
            writer.add_metadata(
                EXPORT_METADATA_NAME,
                {
                    "source": log.name,
                    "source_sha256": checked.sha256,
                    "source_library": header.library if header else "",
                    "smc_version": __version__,
                    "format": "ros2",
                },
            )
            for a in raw.attachments:
                writer.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
            schemas: dict[str, Schema] = {}  # registered on first use, as rosbag2 does
            for m in raw.messages:
                _write(writer, convert, raw.topic(m), m, types, schemas, counts, skipped)
            writer.finish()
            f.flush()
            os.fsync(f.fileno())
        os.replace(part, out)
    except BaseException:
        part.unlink(missing_ok=True)
        raise
    ordered = {ros: counts[ros] for ros in types if ros in counts}
    return ExportSummary(
        out=out,
        messages=ordered,
        types={ros: types[ros] for ros in ordered},
        size_bytes=out.stat().st_size,
        source_bytes=len(data),
        skipped=skipped,
        scene=checked.metadata.get("scene", ""),
    )


def _write(
    writer: Ros2Writer,
    convert: _Converter,
    topic: str,
    m: Message,
    types: dict[str, str],
    schemas: dict[str, Schema],
    counts: dict[str, int],
    skipped: dict[str, int],
) -> None:
    """Convert one native message and write what it becomes (or count it as skipped)."""
    if topic not in _METHODS:
        skipped[topic] = skipped.get(topic, 0) + 1
        return
    converted = convert.convert(topic, m.log_time, m.data)
    if not converted:
        skipped[topic] = skipped.get(topic, 0) + 1
    for ros, msg in converted:
        kind = types[ros]
        if kind not in schemas:
            schemas[kind] = writer.register_msgdef(kind, msgdef(kind))
        writer.write_message(ros, schemas[kind], msg, log_time=m.log_time, publish_time=m.log_time)
        counts[ros] = counts.get(ros, 0) + 1
