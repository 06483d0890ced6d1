"""Topic table and message codecs: what each MCAP topic holds and how it is (de)serialised.

Protobuf topics use the Foxglove well-known schemas (schema encoding ``protobuf``, schema
data = a serialized FileDescriptorSet) so the log opens in Foxglove and in Rerun's MCAP
importer. Our own topics are JSON (message encoding ``json``) with the JSON Schema from
``schemas/`` as schema data (schema encoding ``jsonschema``).

Times: seconds (float) in memory, integer nanoseconds in the log (``to_ns``).
"""

from __future__ import annotations

import functools
import json
from typing import Any

import cv2
import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.JointStates_pb2 import JointStates
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from google.protobuf.message import Message as ProtoMessage

from smccli.schemas import schema_path

COMMAND = "/teleop/command"
JOINT_STATES = "/robot/joint_states"
POI = "/robot/poi"
BASE = "/robot/base"
"""A mobile manipulator's base pose (odometry); its ``/robot/poi`` is then in frame ``base``."""
COLOR = "/camera/color"
DEPTH = "/camera/depth"
CALIBRATION = "/camera/calibration"
TF = "/tf"
SCAN = "/lidar/scan"
SCAN_POINTS = "/lidar/points"
POINTS = "/perception/points"
WEIGHT = "/scale/weight"
SALIENCY = "/saliency"
GROUND_TRUTH = "/sim/ground_truth"
DECISION = "/smc/decision"

ARM_TOPICS = frozenset({COMMAND, POI, JOINT_STATES, COLOR, DEPTH, CALIBRATION})
"""Topics every arm log must hold for compile."""
BASE_TOPICS = frozenset({COMMAND, POI, JOINT_STATES, COLOR, SCAN})
"""Topics every mobile-base log must hold for compile."""
READ_TOPICS = ARM_TOPICS | BASE_TOPICS | {TF, WEIGHT, SALIENCY, BASE}
"""Topics compile reads; the ground truth is deliberately not among them."""

PROTO_TOPICS: dict[str, type[ProtoMessage]] = {
    JOINT_STATES: JointStates,
    POI: PoseInFrame,
    BASE: PoseInFrame,
    COLOR: CompressedImage,
    DEPTH: CompressedImage,
    CALIBRATION: CameraCalibration,
    TF: FrameTransforms,
    SCAN: LaserScan,
    SCAN_POINTS: PointCloud,
    POINTS: PointCloud,
}
"""Protobuf topic -> Foxglove message class."""

JSON_TOPICS: dict[str, str] = {
    COMMAND: "teleop_command",
    WEIGHT: "weight",
    SALIENCY: "saliency",
    GROUND_TRUTH: "ground_truth",
    DECISION: "smc_decision",
}
"""JSON topic -> schema file stem in ``schemas/`` (``<stem>.schema.json``)."""

METADATA_NAME = "smc"
END_METADATA_NAME = "smc_end"
"""Metadata record written when a recording is closed: ``end`` = complete | interrupted."""
WORLD = "world"
BASE_FRAME = "base"
DEPTH_SCALE = 1000.0
"""Depth PNG units per metre: 16-bit millimetres, 0 = no return, range up to 65.535 m."""


def to_ns(t: float) -> int:
    """Simulation time [s] -> log time [ns]; rounding makes it deterministic."""
    return int(round(t * 1e9))


@functools.cache
def json_schema_bytes(topic: str) -> bytes:
    """The JSON Schema file of a JSON topic, byte for byte as stored in the log."""
    return schema_path(JSON_TOPICS[topic]).read_bytes()


@functools.cache
def json_schema_name(topic: str) -> str:
    return str(json.loads(json_schema_bytes(topic))["title"])


@functools.cache
def json_validator(topic: str) -> Any:
    """The topic's JSON Schema validator, built once per topic (writing and reading)."""
    import jsonschema  # imported on first use: slow to import, and most commands never validate

    schema = json.loads(json_schema_bytes(topic))
    return jsonschema.Draft202012Validator(schema)


def encode_json(obj: Any) -> bytes:
    """Deterministic JSON: sorted keys, no spaces; NaN/inf refused (not valid JSON)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()


def stamp(msg: Any, t_ns: int) -> None:
    msg.timestamp.FromNanoseconds(t_ns)


# --- poses (quaternions are w, x, y, z: smccli.world.geometry; foxglove names its fields) ---


def set_pose(pose: Any, position: np.ndarray, quat: np.ndarray) -> None:
    """Fill a foxglove Pose (or the translation/rotation pair of a FrameTransform)."""
    p = pose.position if hasattr(pose, "position") else pose.translation
    o = pose.orientation if hasattr(pose, "orientation") else pose.rotation
    p.x, p.y, p.z = (float(v) for v in position)
    o.w, o.x, o.y, o.z = (float(v) for v in quat)


def get_pose(pose: Any) -> tuple[np.ndarray, np.ndarray]:
    """Position (3,) and quaternion (4,) wxyz of a foxglove Pose or FrameTransform."""
    p = pose.position if hasattr(pose, "position") else pose.translation
    o = pose.orientation if hasattr(pose, "orientation") else pose.rotation
    return np.array([p.x, p.y, p.z]), np.array([o.w, o.x, o.y, o.z])


# --- images ---


def encode_color(rgb: np.ndarray, jpeg_quality: int | None) -> tuple[str, bytes]:
    """RGB (H, W, 3) uint8 -> (format, bytes): JPEG at ``jpeg_quality`` or lossless PNG if None."""
    bgr = np.ascontiguousarray(rgb[..., ::-1])
    if jpeg_quality is None:
        ok, buf = cv2.imencode(".png", bgr)
        fmt = "png"
    else:
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
        fmt = "jpeg"
    if not ok:
        raise ValueError(f"cannot encode a colour image of shape {rgb.shape}")
    return fmt, buf.tobytes()


def encode_depth(depth: np.ndarray) -> bytes:
    """Depth (H, W) [m] -> 16-bit PNG in millimetres; 0, inf, NaN and > 65.535 m become 0."""
    d = np.nan_to_num(np.asarray(depth, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    mm = np.round(d * DEPTH_SCALE)
    mm[(mm < 0) | (mm > 65535)] = 0
    ok, buf = cv2.imencode(".png", mm.astype(np.uint16))
    if not ok:
        raise ValueError(f"cannot encode a depth image of shape {depth.shape}")
    return buf.tobytes()


def decode_image(data: bytes) -> np.ndarray | None:
    """Compressed image bytes -> array as stored (colour comes back BGR, depth as uint16);
    None when the bytes do not decode (the caller says which message)."""
    if not data:
        return None  # cv2.imdecode asserts on an empty buffer
    # OpenCV logs broken input to stderr (a torn PNG, chunks out of order); the caller
    # reports the failure itself, as one line naming the message.
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error:  # how OpenCV reports some malformed inputs (it returns None for most)
        return None
    finally:
        cv2.utils.logging.setLogLevel(level)


def decode_color(data: bytes) -> np.ndarray | None:
    img = decode_image(data)
    if img is None or img.ndim != 3:
        return None
    return np.ascontiguousarray(img[..., 2::-1])
