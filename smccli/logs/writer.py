"""LogWriter: crash-safe MCAP recording of one demonstration (docs/design.md section 3)."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType
from typing import IO, TYPE_CHECKING, Any

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.JointStates_pb2 import JointStates
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from mcap.writer import CompressionType, Writer
from mcap_protobuf.schema import build_file_descriptor_set

from smccli import __version__
from smccli.errors import LogError, OutputExistsError
from smccli.logs import topics as tp
from smccli.outputs import check_output
from smccli.world.geometry import matrix_quat, yaw_quat
from smccli.world.scene import ASSET_PREFIX
from smccli.world.sensors import CameraFrame, JointState, PoiCommand, SaliencyMark

if TYPE_CHECKING:
    from smccli.world.scene import Scene
    from smccli.world.sim import Sim


def part_path(path: Path) -> Path:
    """Where a log is written until it is closed cleanly: ``NAME.mcap.part``."""
    return path.with_name(path.name + ".part")


def _finite(name: str, a: Any) -> np.ndarray:
    arr = np.asarray(a, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} holds NaN or inf: {arr.tolist()}")
    return arr


class LogWriter:
    """Writes ``PATH.part`` and renames it to ``PATH`` on a clean ``close()``.

    The current chunk is ended at least every ``flush_period_s`` of log time and (with
    ``wall_clock_flush``, from a background thread) of wall time, so a killed process
    loses at most about that much. ``wall_clock_flush=False`` makes chunk boundaries, and
    so the whole file, a function of the inputs only (for reproducible sample logs).
    An exception inside ``with`` (or ``abort()``) removes the ``.part``; ``PATH`` is untouched.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        metadata: Mapping[str, str],
        attachments: Mapping[str, tuple[str, bytes]] | None = None,
        force: bool = False,
        flush_period_s: float = 1.0,
        wall_clock_flush: bool = True,
        jpeg_quality: int | None = 90,
    ) -> None:
        self.path = Path(path)
        self.part = part_path(self.path)
        check_output(self.path, force=force)
        if self.part.exists() and not force:
            # A killed recorder's file: the only copy of that demonstration.
            raise OutputExistsError(
                f"{self.part}: exists (an unfinished recording; keep it with "
                f"`smc doctor {self.part} --repair OUT`, or use --force to overwrite)"
            )
        self.flush_period_s = float(flush_period_s)
        self.jpeg_quality = jpeg_quality
        self.counts: dict[str, int] = {}
        """Messages written per topic, for live status and the summary."""
        self._lock = threading.Lock()
        self._closed = False
        self._channels: dict[str, int] = {}
        self._last_t: dict[str, int] = {}
        self._last_flush_log_ns: int | None = None
        self._max_t_ns = 0
        """Latest log time written [ns]."""
        self._on_disk_ns = 0
        """Latest log time whose chunk has been written out [ns]."""
        self._last_flush_wall = time.monotonic()
        self._file: IO[bytes] = open(self.part, "wb")
        try:
            self._mcap = Writer(self._file, compression=CompressionType.ZSTD)
            self._mcap.start(profile="", library=f"smc {__version__}")
            meta = {"smc_version": __version__, **{str(k): str(v) for k, v in metadata.items()}}
            self._mcap.add_metadata(tp.METADATA_NAME, meta)
            for name, (media_type, data) in sorted((attachments or {}).items()):
                self._mcap.add_attachment(0, 0, name, media_type, bytes(data))
            self._file.flush()  # header, metadata and attachments survive any crash
        except BaseException:
            self._file.close()
            self.part.unlink(missing_ok=True)
            raise
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        if wall_clock_flush:
            self._thread = threading.Thread(target=self._flush_loop, daemon=True)
            self._thread.start()

    # --- lifecycle ---

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def close(
        self, *, interrupted: str | None = None, end_fields: dict[str, str] | None = None
    ) -> Path:
        """Finish the file (summary, index) and rename it to ``path`` atomically.

        A metadata record ``smc_end`` says how the recording ended: ``end`` is ``complete``,
        or ``interrupted`` with ``reason`` (e.g. ``SIGINT``) when ``interrupted`` is given;
        ``end_fields`` adds to it (the recorder's ``task``: whether the demonstration
        achieved it).
        """
        if self._closed:
            return self.path
        self._stop_thread()
        with self._lock:
            self._closed = True
            end = {"end": "complete" if interrupted is None else "interrupted"}
            if interrupted is not None:
                end["reason"] = interrupted
            end["last_log_time_s"] = f"{self._max_t_ns / 1e9:.3f}"
            end.update(end_fields or {})
            self._mcap.add_metadata(tp.END_METADATA_NAME, end)
            self._mcap.finish()
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
        os.replace(self.part, self.path)
        return self.path

    def abort(self) -> None:
        """Drop the recording: close and remove the ``.part``."""
        if self._closed:
            return
        self._stop_thread()
        with self._lock:
            self._closed = True
            self._file.close()
        self.part.unlink(missing_ok=True)

    @property
    def t_on_disk(self) -> float:
        """Log time [s] up to which every message has reached the file (the last chunk end)."""
        return self._on_disk_ns / 1e9

    @property
    def size_bytes(self) -> int:
        """Bytes on disk so far (the chunk being built is not counted)."""
        try:
            return (self.path if self._closed else self.part).stat().st_size
        except FileNotFoundError:
            return 0

    def _stop_thread(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()

    def _flush_loop(self) -> None:
        # Wall-time flushes matter when log time advances slowly or stalls (keyboard operator
        # idle, a slow step): the buffered chunk must still reach the disk within a period.
        while not self._stop.wait(self.flush_period_s / 4):
            with self._lock:
                if self._closed:
                    return
                if time.monotonic() - self._last_flush_wall >= self.flush_period_s:
                    self._flush_locked()

    def _flush_locked(self) -> None:
        self._mcap.flush()  # ends the chunk and flushes the file object
        self._last_flush_wall = time.monotonic()
        self._on_disk_ns = self._max_t_ns

    # --- low level ---

    def _channel(self, topic: str) -> int:
        if topic in self._channels:
            return self._channels[topic]
        if topic in tp.PROTO_TOPICS:
            cls = tp.PROTO_TOPICS[topic]
            fds = build_file_descriptor_set(cls).SerializeToString()
            sid = self._mcap.register_schema(cls.DESCRIPTOR.full_name, "protobuf", fds)
            cid = self._mcap.register_channel(topic, "protobuf", sid)
        elif topic in tp.JSON_TOPICS:
            name, data = tp.json_schema_name(topic), tp.json_schema_bytes(topic)
            sid = self._mcap.register_schema(name, "jsonschema", data)
            cid = self._mcap.register_channel(topic, "json", sid)
        else:
            known = sorted([*tp.PROTO_TOPICS, *tp.JSON_TOPICS])
            raise ValueError(f"unknown topic {topic!r}; known: {', '.join(known)}")
        self._channels[topic] = cid
        return cid

    def _write(self, topic: str, t_ns: int, data: bytes) -> None:
        with self._lock:
            if self._closed:
                raise LogError(f"{self.path}: write to {topic} after close")
            last = self._last_t.get(topic)
            if last is not None and t_ns < last:
                raise LogError(
                    f"{self.path}: time goes backwards on {topic}: {t_ns / 1e9:.9f} s "
                    f"after {last / 1e9:.9f} s"
                )
            self._last_t[topic] = t_ns
            self._max_t_ns = max(self._max_t_ns, t_ns)
            cid = self._channel(topic)
            self._mcap.add_message(cid, log_time=t_ns, data=data, publish_time=t_ns)
            self.counts[topic] = self.counts.get(topic, 0) + 1
            if self._last_flush_log_ns is None:
                self._last_flush_log_ns = t_ns
            elif t_ns - self._last_flush_log_ns >= self.flush_period_s * 1e9:
                self._last_flush_log_ns = t_ns
                self._flush_locked()

    def _proto(self, topic: str, t_ns: int, msg: Any) -> None:
        self._write(topic, t_ns, msg.SerializeToString())

    def write_json(self, topic: str, t: float, obj: Any) -> None:
        """A JSON message on a registered JSON topic, validated against its schema."""
        if topic not in tp.JSON_TOPICS:
            raise ValueError(
                f"{topic!r} is not a JSON topic; JSON topics: {sorted(tp.JSON_TOPICS)}"
            )
        data = tp.encode_json(obj)
        errors = sorted(tp.json_validator(topic).iter_errors(obj), key=str)
        if errors:
            raise ValueError(f"{topic}: message does not match its schema: {errors[0].message}")
        self._write(topic, tp.to_ns(t), data)

    # --- typed messages ---

    def write_command(self, cmd: PoiCommand) -> None:
        """A command, checked here against what its schema asks (4 finite target numbers,
        3 for a base, an opening in [0, 1]): a recording writes one per control period,
        and the schema's validator made each cost 2.6 times as much (177 against 67 µs)."""
        target = _finite("command target", cmd.target)
        gripper = float(cmd.gripper)
        msg: dict[str, Any] = {"target": target.tolist(), "gripper": gripper}
        if cmd.base is not None:
            msg["base_target"] = _finite("command base target", cmd.base).tolist()
        shapes = target.shape == (4,) and (cmd.base is None or len(msg["base_target"]) == 3)
        if not (shapes and 0.0 <= gripper <= 1.0):
            raise ValueError(f"{tp.COMMAND}: message does not match its schema: {msg}")
        self._write(tp.COMMAND, tp.to_ns(cmd.t), tp.encode_json(msg))

    def write_joint_state(self, js: JointState) -> None:
        msg = JointStates()
        tp.stamp(msg, tp.to_ns(js.t))
        for i, name in enumerate(js.names):
            msg.joints.add(
                name=name,
                position=float(js.position[i]),
                velocity=float(js.velocity[i]),
                effort=float(js.effort[i]),
            )
        self._proto(tp.JOINT_STATES, tp.to_ns(js.t), msg)

    def write_poi(self, t: float, poi: np.ndarray, frame: str = tp.WORLD) -> None:
        """POI ``[x, y, z, yaw]`` as a PoseInFrame (rotation about z) in ``frame`` (a mobile
        manipulator's: ``base``) and tf frame->poi."""
        p = _finite("POI", poi)
        t_ns, q = tp.to_ns(t), yaw_quat(float(p[3]))
        msg = PoseInFrame(frame_id=frame)
        tp.stamp(msg, t_ns)
        tp.set_pose(msg.pose, p[:3], q)
        self._proto(tp.POI, t_ns, msg)
        self._tf(t_ns, "poi", p[:3], q, parent=frame)

    def write_base(self, t: float, pose: np.ndarray) -> None:
        """A mobile manipulator's base pose ``[x, y, yaw]`` (odometry) on ``/robot/base``
        and tf world->base."""
        p = _finite("base pose", pose)
        t_ns, q = tp.to_ns(t), yaw_quat(float(p[2]))
        position = np.array([p[0], p[1], 0.0])
        msg = PoseInFrame(frame_id=tp.WORLD)
        tp.stamp(msg, t_ns)
        tp.set_pose(msg.pose, position, q)
        self._proto(tp.BASE, t_ns, msg)
        self._tf(t_ns, tp.BASE_FRAME, position, q)

    def _tf(
        self,
        t_ns: int,
        child: str,
        position: np.ndarray,
        quat: np.ndarray,
        parent: str = tp.WORLD,
    ) -> None:
        msg = FrameTransforms()
        tr = msg.transforms.add(parent_frame_id=parent, child_frame_id=child)
        tp.stamp(tr, t_ns)
        tp.set_pose(tr, position, quat)
        self._proto(tp.TF, t_ns, msg)

    def write_camera(self, frame: CameraFrame) -> None:
        """Colour, depth (PNG 16-bit mm), calibration and tf world->camera, all at ``frame.t``."""
        t_ns = tp.to_ns(frame.t)
        T = _finite("T_world_camera", frame.T_world_camera)
        K = _finite("K", frame.K)
        h, w = frame.rgb.shape[:2]
        fmt, data = tp.encode_color(frame.rgb, self.jpeg_quality)
        color = CompressedImage(frame_id=frame.frame_id, format=fmt, data=data)
        tp.stamp(color, t_ns)
        self._proto(tp.COLOR, t_ns, color)
        depth = CompressedImage(
            frame_id=frame.frame_id, format="png", data=tp.encode_depth(frame.depth)
        )
        tp.stamp(depth, t_ns)
        self._proto(tp.DEPTH, t_ns, depth)
        P = np.zeros((3, 4))
        P[:, :3] = K
        calib = CameraCalibration(
            frame_id=frame.frame_id,
            width=w,
            height=h,
            distortion_model="plumb_bob",
            D=[0.0] * 5,
            K=K.ravel().tolist(),
            R=np.eye(3).ravel().tolist(),
            P=P.ravel().tolist(),
        )
        tp.stamp(calib, t_ns)
        self._proto(tp.CALIBRATION, t_ns, calib)
        self._tf(t_ns, frame.frame_id, T[:3, 3], matrix_quat(T[:3, :3]))

    def write_weight(self, t: float, kg: float) -> None:
        self.write_json(tp.WEIGHT, t, {"kg": float(kg)})

    def write_saliency(self, mark: SaliencyMark) -> None:
        self.write_json(tp.SALIENCY, mark.t, {"source": mark.source, "label": mark.label})

    def write_ground_truth(self, t: float, poses: Mapping[str, np.ndarray]) -> None:
        """Object poses, name -> (7,) ``[x, y, z, qw, qx, qy, qz]`` world frame."""
        obj = {name: _finite(f"pose of {name}", p).tolist() for name, p in sorted(poses.items())}
        self.write_json(tp.GROUND_TRUTH, t, {"poses": obj})

    def write_point_cloud(
        self,
        t: float,
        points: np.ndarray,
        colors: np.ndarray | None = None,
        frame_id: str = tp.WORLD,
        topic: str = tp.POINTS,
    ) -> None:
        """Points (N, 3) float32 [m] in ``frame_id``, optional colours (N, 3) uint8 RGB, on
        ``topic``."""
        pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        msg = PointCloud(frame_id=frame_id)
        tp.stamp(msg, tp.to_ns(t))
        msg.pose.orientation.w = 1.0
        F = PackedElementField
        for i, name in enumerate("xyz"):
            msg.fields.add(name=name, offset=4 * i, type=F.FLOAT32)
        if colors is None:
            msg.point_stride = 12
            msg.data = pts.tobytes()
        else:
            # 16-byte records: x y z float32 + r g b a uint8 (the layout Foxglove documents)
            rec = np.zeros(len(pts), dtype=[("p", "<f4", 3), ("c", "u1", 4)])
            rec["p"] = pts
            rec["c"][:, :3] = np.asarray(colors, dtype=np.uint8).reshape(-1, 3)
            rec["c"][:, 3] = 255
            for i, name in enumerate(("red", "green", "blue", "alpha")):
                msg.fields.add(name=name, offset=12 + i, type=F.UINT8)
            msg.point_stride = 16
            msg.data = rec.tobytes()
        self._proto(topic, tp.to_ns(t), msg)

    def write_scan(
        self,
        t: float,
        ranges: np.ndarray,
        *,
        start_angle: float,
        end_angle: float,
        intensities: np.ndarray | None = None,
        frame_id: str = "lidar",
        T_frame_scan: np.ndarray | None = None,
        T_world_frame: np.ndarray | None = None,
    ) -> None:
        """A planar scan: ``ranges`` (N,) [m] evenly spaced from start to end angle [rad].

        ``T_frame_scan`` (4, 4) is the scan origin in ``frame_id`` (identity by default);
        ``T_world_frame`` (4, 4), when given, is also published on ``/tf`` (world ->
        ``frame_id``), so viewers place the scan in the world.
        """
        if T_world_frame is not None:
            W = np.asarray(T_world_frame, dtype=float)
            self._tf(tp.to_ns(t), frame_id, W[:3, 3], matrix_quat(W[:3, :3]))
        msg = LaserScan(frame_id=frame_id, start_angle=start_angle, end_angle=end_angle)
        tp.stamp(msg, tp.to_ns(t))
        msg.ranges.extend(np.asarray(ranges, dtype=float).tolist())
        if intensities is not None:
            msg.intensities.extend(np.asarray(intensities, dtype=float).tolist())
        T = np.eye(4) if T_frame_scan is None else np.asarray(T_frame_scan, dtype=float)
        tp.set_pose(msg.pose, T[:3, 3], matrix_quat(T[:3, :3]))
        self._proto(tp.SCAN, tp.to_ns(t), msg)

    def write_robot_pose(self, sim: Sim) -> None:
        """The robot's POI now; a mobile manipulator's in frame ``base``, with the base's
        pose (odometry) on ``/robot/base``."""
        if sim.mobile_manipulator:
            self.write_base(sim.t, sim.base_odometry())
            self.write_poi(sim.t, sim.poi(), frame=tp.BASE_FRAME)
        else:
            self.write_poi(sim.t, sim.poi())

    def write_lidar(self, sim: Sim) -> None:
        """The robot's lidar scan now, if it has one: ``/lidar/scan`` in the lidar's own
        frame, and that frame on ``/tf`` where odometry puts it (the lidar's height from its
        mounting)."""
        scan = sim.lidar()
        pose = sim.lidar_pose()
        if scan is None or pose is None:
            return
        end = scan.angle_min + scan.angle_increment * (len(scan.ranges) - 1)
        x, y, yaw = pose
        T = np.eye(4)
        T[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
        T[:3, 3] = [x, y, sim.lidar_height()]
        self.write_scan(
            scan.t, scan.ranges, start_angle=scan.angle_min, end_angle=end, T_world_frame=T
        )
        # The returns as points too: viewers without a LaserScan decoder (Rerun's MCAP
        # importer) show these in the lidar's frame.
        ok = np.isfinite(scan.ranges)
        a = scan.angle_min + scan.angle_increment * np.flatnonzero(ok)
        r = scan.ranges[ok]
        pts = np.stack([r * np.cos(a), r * np.sin(a), np.zeros_like(r)], axis=1)
        self.write_point_cloud(scan.t, pts, frame_id="lidar", topic=tp.SCAN_POINTS)


def scene_attachments(scene: Scene) -> dict[str, tuple[str, bytes]]:
    """The scene's MJCF and YAML and the robot file, attached to every log so it is
    self-contained."""
    return {
        "scene.xml": ("application/xml", scene.mjcf.encode()),
        "scene.yaml": ("application/yaml", scene.yaml_text.encode()),
        "robot.yaml": ("application/yaml", scene.robot.yaml_text.encode()),
        # The files the MJCF names (a vendor robot's meshes): the log opens anywhere.
        **{f"{ASSET_PREFIX}{n}": ("application/octet-stream", b) for n, b in scene.assets},
    }
