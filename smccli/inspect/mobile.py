"""The mobile base's layers (a tree with room / scan perceptions, or a log with
``/lidar/scan``), drawn from its scene: what :class:`MobileView` takes from it.

- ``/world/rooms``: the scene's regions as closed line strips on the floor, labelled with
  their names, and ``/world/places`` its named places as arrows (static, if it has any).
- ``/world/actions/<edge>/scan``: the SMC's stored scan drawn in the world at its
  ``scan_pose``, ``.../scan_pose`` that pose and ``.../goal_pose`` the goal in the world
  (a scan-frame goal composed with ``scan_pose``), as arrows.
- ``/world/lidar/scan``: each scan's returns in the world (placed by the lidar's odometry
  pose: the POI composed with the lidar's mounting; scans thinned in time to at most
  ``MAX_SCAN_POINTS`` points), ``/world/lidar/pose`` the lidar's pose as an arrow.
- ``/world/base``: the base's footprint as a box, ``/world/base/heading`` its heading.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

import numpy as np

from smccli.errors import SmcError
from smccli.inspect.labels import HIGHLIGHT, PALETTE, SCAN_RGB, Rgb
from smccli.inspect.views import TIMELINE
from smccli.learn.frames import goal_at_scan_pose
from smccli.learn.tree import Edge, Tree
from smccli.world.geometry import compose, from_frame, wrap_yaw, xyzw, yaw_of, yaw_quat
from smccli.world.robot import robot_geoms

if TYPE_CHECKING:
    import rerun as rr

    from smccli.logs.log import Log
    from smccli.world.scene import Scene

MAX_SCAN_POINTS = 100_000
"""A log's lidar scans are thinned in time to at most this many returns in all (every
scan of a 26 s log at 10 Hz, 360 beams, fits)."""


@dataclass(frozen=True, slots=True)
class MobileView:
    """What drawing a mobile base takes from its scene (defaults when it is unknown)."""

    regions: tuple[tuple[str, tuple[tuple[float, float, float, float], ...]], ...] = ()
    """The scene's rooms, each a union of rectangles (x_min, x_max, y_min, y_max) [m]."""
    places: tuple[tuple[str, tuple[float, float, float]], ...] = ()
    """The scene's named base poses (x, y, yaw) [m, m, rad]."""
    mount: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """The lidar's planar pose in the POI's frame ``[x, y, yaw]`` [m, m, rad]."""
    lidar_z: float = 0.0
    """Height of the lidar's scan plane [m]: scans are drawn there."""
    footprint: tuple[float, float, float, float] | None = None
    """The robot's outline in the POI's frame (x_min, x_max, y_min, y_max) [m], if known."""


_ARROW = 0.35
"""Length of a pose arrow [m]."""


class PoseArrows(TypedDict):
    """Arrows3D's ``origins`` and ``vectors`` (pass them as ``**``)."""

    origins: np.ndarray
    vectors: np.ndarray


def _tree_is_mobile(tree: Tree) -> bool:
    return any(
        e.smc.perception.room is not None
        or e.smc.perception.scan is not None
        or e.smc.action.goal_frame == "scan"
        for e in tree.edges
    )


def is_mobile(tree: Tree, logs: Sequence[Log]) -> bool:
    """Whether the tree or a log is a mobile base's (room / scan perceptions, lidar scans)."""
    return _tree_is_mobile(tree) or any(getattr(log, "scans", None) for log in logs)


def _scene_geometry(scene: Scene) -> MobileView:
    """Rooms, places, lidar mounting and footprint of a scene's robot, from its model at its
    reference configuration."""
    import mujoco

    from smccli.world.lidar import lidar_mount

    model = scene.model()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    robot = scene.robot
    lidar = next((m for m in robot.sensors if m.type == "lidar"), None)
    mount, lidar_z = np.zeros(3), 0.0
    if lidar is not None:
        # A mobile manipulator's base pose is its own POI (the hand is the other one).
        mount = lidar_mount(model, None if robot.arm_joints else robot.poi, lidar.target)
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, lidar.target)
        lidar_z = float(data.site_xpos[sid][2])
    footprint = None
    pid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, robot.poi)
    own = robot_geoms(robot, model)
    if pid >= 0 and len(own) and not robot.arm_joints:
        yaw = yaw_of(data.site_xmat[pid])
        signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])
        corners = []
        for g in own:
            centre, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
            local = centre + signs * half
            corners.append(local @ data.geom_xmat[g].reshape(3, 3).T + data.geom_xpos[g])
        xy = np.concatenate(corners)[:, :2] - data.site_xpos[pid][:2]
        c, s = math.cos(yaw), math.sin(yaw)
        xy = xy @ np.array([[c, -s], [s, c]])  # into the POI's frame
        if np.all(np.isfinite(xy)):
            lo, hi = xy.min(axis=0), xy.max(axis=0)
            footprint = (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))
    return MobileView(scene.regions, scene.places, mount, lidar_z, footprint)


def mobile_view(
    tree: Tree, log: Log | None, warn: Callable[[str], None] = lambda m: None
) -> MobileView | None:
    """How to draw a mobile base, or None for an arm (tree and log without room / scan
    perceptions and lidar scans). The scene is the log's (its attachments), else the
    tree's built-in scene by name; without one, the lidar sits on the POI at z = 0."""
    if not (_tree_is_mobile(tree) or (log is not None and log.scans)):
        return None
    from smccli.world.scene import builtin_names, load_scene, scene_of_log

    name = str(tree.scene.get("name", ""))
    try:
        if log is not None:
            scene = scene_of_log(log.attachments, log.path)
        elif name in builtin_names():
            scene = load_scene(name)
            digest = tree.scene.get("digest")
            if digest and digest != scene.digest:
                warn(
                    f"scene {name} changed since the tree was compiled; rooms drawn from "
                    "the current scene file"
                )
        else:
            warn(f"scene {name or '?'} is not built in: rooms and the robot's footprint not drawn")
            return MobileView()
        return _scene_geometry(scene)
    except (SmcError, ValueError) as exc:
        where = Path(log.path).name if log is not None else f"scene {name}"
        warn(
            f"{where}: no scene to draw the rooms and place the lidar "
            f"({str(exc).splitlines()[0]}); the lidar is drawn at the POI"
        )
        return MobileView()


def pose_arrows(poses: np.ndarray, z: float, length: float = _ARROW) -> PoseArrows:
    """Arrows3D's ``origins`` and ``vectors`` for planar poses ``[x, y, yaw]``, each of
    shape (N, 3): at height ``z``, ``length`` long along the yaw."""
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    origins = np.column_stack([poses[:, 0], poses[:, 1], np.full(len(poses), z)])
    vectors = np.column_stack(
        [length * np.cos(poses[:, 2]), length * np.sin(poses[:, 2]), np.zeros(len(poses))]
    )
    return PoseArrows(origins=origins, vectors=vectors)


def _in_world(points: np.ndarray, pose: np.ndarray, z: float) -> np.ndarray:
    """2-D points in a frame at planar ``pose`` -> (N, 3) world points at height ``z``."""
    xy = from_frame(pose, points)
    return np.column_stack([xy, np.full(len(xy), z)])


def goal_pose_world(edge: Edge) -> np.ndarray | None:
    """A base SMC's goal in the world ``[x, y, yaw]``: a scan-frame goal composed with its
    scan pose; a world goal as it is; None for an object-frame goal."""
    a, p = edge.smc.action, edge.smc.perception
    g = np.asarray(a.goal, dtype=float)
    if a.goal_frame == "scan" and p.scan_pose is not None and len(g) == 4:
        return goal_at_scan_pose(g[[0, 1, 3]], np.asarray(p.scan_pose, dtype=float))
    if a.goal_frame == "world" and len(g) == 4:
        return g[[0, 1, 3]]
    return None


def log_stored_scan(rec: rr.RecordingStream, edge: Edge, colour: Rgb, mobile: MobileView) -> None:
    """An SMC's stored scan in the world at its scan pose, that pose and its goal (static)."""
    import rerun as rr

    base = f"/world/actions/{edge.id}"
    p = edge.smc.perception
    if p.scan is not None and p.scan_pose is not None:
        pose = np.asarray(p.scan_pose, dtype=float)
        pts = _in_world(p.scan.points(), pose, mobile.lidar_z)
        rec.log(
            f"{base}/scan",
            rr.Points3D(pts, colors=[colour], radii=0.012, labels=[f"{edge.id} scan"]),
            static=True,
        )
        arrows = pose_arrows(pose, mobile.lidar_z)
        label = f"{edge.id} scan taken here"
        rec.log(
            f"{base}/scan_pose",
            rr.Arrows3D(**arrows, colors=[colour], radii=0.015, labels=[label]),
            static=True,
        )
    goal = goal_pose_world(edge)
    if goal is not None:
        label = f"{edge.id} goal ({edge.smc.action.goal_frame} frame)"
        rec.log(
            f"{base}/goal_pose",
            rr.Arrows3D(**pose_arrows(goal, 0.02), colors=[colour], radii=0.025, labels=[label]),
            static=True,
        )


def log_rooms(rec: rr.RecordingStream, mobile: MobileView) -> None:
    """The scene's rooms as closed outlines on the floor and its places as arrows (static)."""
    import rerun as rr

    strips, colours, labels = [], [], []
    for k, (name, rects) in enumerate(mobile.regions):
        for x0, x1, y0, y1 in rects:
            strips.append([(x0, y0, 0.0), (x1, y0, 0.0), (x1, y1, 0.0), (x0, y1, 0.0)])
            strips[-1].append(strips[-1][0])  # closed
            colours.append(PALETTE[k % len(PALETTE)])
            labels.append(name)
    if strips:
        rec.log(
            "/world/rooms",
            rr.LineStrips3D(strips, colors=colours, radii=0.02, labels=labels),
            static=True,
        )
    if mobile.places:
        poses = np.array([p for _, p in mobile.places], dtype=float)
        rec.log(
            "/world/places",
            rr.Arrows3D(
                **pose_arrows(poses, 0.01, 0.25),
                colors=[(150, 150, 150)],
                radii=0.01,
                labels=[n for n, _ in mobile.places],
            ),
            static=True,
        )


def _lidar_poses(log: Log, times: np.ndarray, mobile: MobileView) -> np.ndarray:
    """The lidar's planar poses ``[x, y, yaw]`` at ``times``: the POI (odometry)
    interpolated there, composed with the lidar's mounting; shape (N, 3)."""
    bt, base = base_track(log)
    poi = np.column_stack([np.interp(times, bt, base[:, i]) for i in (0, 1, 3)])
    return wrap_yaw(compose(poi, mobile.mount)).reshape(-1, 3)


def base_track(log: Log) -> tuple[np.ndarray, np.ndarray]:
    """A mobile robot's base over time: (times (T,) [s], poses (T, 4) ``[x, y, 0, yaw]``);
    a mobile manipulator's from ``/robot/base`` (its POI is the hand), else the POI."""
    if len(log.base_t):
        b = log.base
        return log.base_t, np.column_stack([b[:, 0], b[:, 1], np.zeros(len(b)), b[:, 2]])
    return log.poi_t, log.poi


def hand_track(log: Log) -> np.ndarray:
    """The POI in the world over time, shape (T, 4): a mobile manipulator's hand (logged in
    its base's frame) composed with its base's pose, else the POI as logged."""
    if not len(log.base_t):
        return np.asarray(log.poi)
    idx = np.clip(np.searchsorted(log.base_t, log.poi_t), 0, len(log.base_t) - 1)
    return compose(log.base[idx], log.poi)


def log_base(rec: rr.RecordingStream, log: Log, mobile: MobileView) -> None:
    """The base's footprint and heading over time (from the POI, i.e. odometry)."""
    import rerun as rr

    bt, base = base_track(log)
    n = len(bt)
    yaw = base[:, 3]
    times = [rr.TimeColumn(TIMELINE, duration=bt)]
    if mobile.footprint is not None:
        x0, x1, y0, y1 = mobile.footprint
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        c, s = np.cos(yaw), np.sin(yaw)
        centres = np.column_stack(
            [base[:, 0] + c * cx - s * cy, base[:, 1] + s * cx + c * cy, np.full(n, 0.03)]
        )
        quats = xyzw(yaw_quat(yaw))
        rec.send_columns(
            "/world/base",
            indexes=times,
            columns=rr.Boxes3D.columns(
                centers=centres,
                half_sizes=np.tile([(x1 - x0) / 2, (y1 - y0) / 2, 0.03], (n, 1)),
                quaternions=quats,
                colors=np.tile(HIGHLIGHT, (n, 1)),
                radii=np.full(n, 0.008),
            ),
        )
    arrows = pose_arrows(base[:, [0, 1, 3]], 0.07)
    rec.send_columns(
        "/world/base/heading",
        indexes=times,
        columns=rr.Arrows3D.columns(
            **arrows, colors=np.tile(HIGHLIGHT, (n, 1)), radii=np.full(n, 0.02)
        ),
    )


def log_scans(rec: rr.RecordingStream, log: Log, mobile: MobileView) -> None:
    """The lidar's returns in the world at each scan (thinned in time to at most
    ``MAX_SCAN_POINTS`` in all) and the lidar's pose at every scan."""
    import rerun as rr

    from smccli.perception.scan import Scan2D
    from smccli.world.lidar import RANGE_MAX

    if not log.scans or not len(log.poi_t):
        return
    t = np.array([sc.t for sc in log.scans])
    poses = _lidar_poses(log, t, mobile)
    rec.send_columns(
        "/world/lidar/pose",
        indexes=[rr.TimeColumn(TIMELINE, duration=t)],
        columns=rr.Arrows3D.columns(
            **pose_arrows(poses, mobile.lidar_z, 0.25),
            colors=np.tile(SCAN_RGB, (len(t), 1)),
            radii=np.full(len(t), 0.015),
        ),
    )
    scans = [
        Scan2D.from_span(sc.ranges, sc.start_angle, sc.end_angle, RANGE_MAX).points()
        for sc in log.scans
    ]
    total = sum(len(p) for p in scans)
    stride = max(1, math.ceil(total / MAX_SCAN_POINTS))
    keep = range(0, len(scans), stride)
    world = [_in_world(scans[i], poses[i], mobile.lidar_z) for i in keep]
    lengths = [len(w) for w in world]
    pts = np.concatenate(world) if world else np.zeros((0, 3))
    rec.send_columns(
        "/world/lidar/scan",
        indexes=[rr.TimeColumn(TIMELINE, duration=t[list(keep)])],
        columns=rr.Points3D.columns(
            positions=pts,
            colors=np.tile(SCAN_RGB, (len(pts), 1)),
            radii=np.full(len(pts), 0.015),
        ).partition(lengths),
    )
