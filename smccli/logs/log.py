"""What a log holds, decoded: :class:`Log` and the messages it collects."""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from smccli.logs.images import decode_color, decode_depth
from smccli.world.geometry import se3
from smccli.world.sensors import CameraFrame, JointState, PoiCommand, SaliencyMark


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
class FrameRecord:
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
    records: tuple[FrameRecord, ...]

    def __len__(self) -> int:
        return len(self.records)

    @property
    def times(self) -> list[float]:
        """Frame times [s], as ``CameraFrame.t``."""
        return [r.t_ns / 1e9 for r in self.records]

    def frame(self, i: int) -> CameraFrame:
        """Decode frame ``i``; LogError (as :func:`read_log`'s) if its image does not decode."""
        r = self.records[i]
        rgb = decode_color(self.path, r.t_ns, r.fmt, r.data)
        depth = np.zeros((0, 0), np.float32)
        if r.depth is not None:
            depth = decode_depth(self.path, r.t_ns, *r.depth, rgb.shape)
        return CameraFrame(r.t_ns / 1e9, rgb, depth, r.K, se3(*r.pose), r.frame_id)


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

    def frame_at(self, t: float) -> CameraFrame | None:
        """First camera frame at or after ``t`` (within 0.2 s), else the last one before. Of a
        log read with ``lazy_frames`` only that frame is decoded."""
        times = self.camera.times if self.camera is not None else [f.t for f in self.frames]
        after = [i for i, ti in enumerate(times) if ti >= t - 1e-6]
        if after and times[after[0]] - t <= 0.2:
            i: int | None = after[0]
        else:
            before = [i for i, ti in enumerate(times) if ti < t]
            i = before[-1] if before else (after[0] if after else None)
        if i is None:
            return None
        return self.camera.frame(i) if self.camera is not None else self.frames[i]

    @property
    def task(self) -> dict[str, Any] | None:
        """What the recorder found at the end of the demonstration (:func:`parse_task`)."""
        return parse_task(self.end)

    @property
    def interrupted(self) -> bool:
        """Whether the recording stopped before its operator finished (signal, repair)."""
        return self.end.get("end") == "interrupted"


def parse_task(end: Mapping[str, str]) -> dict[str, Any] | None:
    """The ``task`` of an ``smc_end`` record: what the recorder found at the end of the
    demonstration, ``{success, reason, criteria}`` (success None: the scene defines no
    task); None when the record does not say (a log cut short, an older recorder, a bag)."""
    raw = end.get("task")
    if not raw:
        return None
    try:
        task = json.loads(raw)
    except json.JSONDecodeError:
        return None
    return task if isinstance(task, dict) and "success" in task else None
