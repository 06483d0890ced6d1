"""A log in a recording, on the timeline ``time`` (simulation seconds):

- ``/world/poi``: the POI (moving point) and ``/world/poi/path`` the path taken;
  ``/world/camera``: pose, pinhole, ``image`` and ``depth``; ``/world/decisions/*``: point
  cloud, clusters and the salient one recomputed at each decision point, and for replays
  the mapped goal and the planned path; ``/world/perception/points``: recorded clouds.
- ``/signals/...``: weight, gripper command, POI coordinates and speed, replay distances.
- ``/events/saliency`` (one TextLog per saliency mark), ``/events/fragments``,
  ``/events/decisions`` (one per ``/smc/decision`` record), ``/events/perception``.

A mobile base's log adds its layers (:mod:`.mobile`) and, at each decision point, room
histograms instead of the point cloud and clusters (a mobile manipulator shows both):
``/signals/room_histogram/camera`` the camera's whole-frame colour histogram (BarChart),
``/signals/room_histogram/smc`` the one stored in the SMC chosen there (replay) or compiled
from there (demonstration). A replay's D_P terms per candidate are at
``/signals/decision/<term>/<edge>`` (``room``, ``scan``, ``icp_fitness``),
``/world/decisions/goal`` the mapped goal as a point and an arrow, ``/world/decisions/lidar``
the lidar's pose there.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from smccli.errors import LogError, SmcError
from smccli.inspect.labels import (
    HIGHLIGHT,
    PATH_RGB,
    SCAN_RGB,
    Rgb,
    branch_colours,
    cluster_name,
    cluster_rgb,
    hist_rgb,
)
from smccli.inspect.mobile import (
    MobileView,
    base_track,
    hand_track,
    log_base,
    log_scans,
    mobile_view,
    pose_arrows,
)
from smccli.inspect.robot_view import log_robot
from smccli.inspect.tree_view import cluster_boxes
from smccli.inspect.views import TIMELINE
from smccli.learn.tree import Edge, Tree
from smccli.perception.colours import colour_name

if TYPE_CHECKING:
    import rerun as rr

    from smccli.logs.log import Log
    from smccli.world.sensors import CameraFrame

MAX_CLOUD_POINTS = 40_000
"""Point clouds are subsampled to at most this many points (viewer and file size)."""


_TERMS = ("room", "scan", "icp_fitness")
"""A base's D_P terms in a decision record, in the order they are shown."""


def _frame_at(frames: Sequence[CameraFrame], t: float) -> CameraFrame:
    """The frame nearest ``t`` (``frames`` is not empty)."""
    times = np.array([f.t for f in frames])
    return frames[int(np.argmin(np.abs(times - t)))]


def _poi_at(log: Log, t: float) -> np.ndarray | None:
    """The POI in the world at ``t`` (a mobile manipulator's hand, :func:`hand_track`)."""
    if len(log.poi_t) == 0:
        return None
    k = int(np.argmin(np.abs(log.poi_t - t)))
    return np.asarray(hand_track(log)[k] if len(log.base_t) else log.poi[k])


def decision_points(log: Log, tree: Tree) -> list[tuple[float, float, str]]:
    """(t0, t1, label) of the log's decision points.

    Replays: the ``/smc/decision`` times (t1 = the next one or the end). Demonstrations:
    the fragments compile would cut (marks snapped to gripper / weight edges); if that
    fails, the operator marks themselves.
    """
    t_end = float(log.poi_t[-1]) if len(log.poi_t) else 0.0
    if log.decisions:
        ts = [float(d["t"]) for d in log.decisions]
        return [
            (t, ts[k + 1] if k + 1 < len(ts) else t_end, f"decision at {d.get('node')}")
            for k, (t, d) in enumerate(zip(ts, log.decisions, strict=True))
        ]
    try:
        from smccli.learn.compile import fragments

        frags = fragments(log, tree.params)
        return [(f.t0, f.t1, f"fragment {k + 1} (ends: {f.cause})") for k, f in enumerate(frags)]
    except Exception:  # a log compile would refuse still shows, cut at its marks
        t0 = float(log.poi_t[0]) if len(log.poi_t) else 0.0
        bounds = [t0, *sorted(m.t for m in log.marks), t_end]
        pairs = zip(bounds[:-1], bounds[1:], strict=True)
        return [(a, b, f"fragment {k + 1}") for k, (a, b) in enumerate(pairs) if b > a]


def log_log(
    rec: rr.RecordingStream,
    log: Log,
    tree: Tree,
    *,
    warn: Callable[[str], None] = lambda m: None,
    perception: bool = True,
    mobile: MobileView | None = None,
) -> None:
    """A demonstration or replay log on the ``time`` timeline (see the module docstring).

    ``mobile``: how to draw a mobile base (default: :func:`mobile_view` of tree and log).
    """
    if mobile is None:
        mobile = mobile_view(tree, log, warn)
    _log_poi(rec, log, mobile)
    _log_weight_and_gripper(rec, log)
    _log_camera(rec, log)
    log_robot(rec, log, warn)
    if mobile is not None:
        if len(log.poi_t):
            log_base(rec, log, mobile)
        log_scans(rec, log, mobile)
    _log_recorded_clouds(rec, log)
    points = decision_points(log, tree)
    _log_marks_and_fragments(rec, log, points)
    _log_decisions(rec, log, tree, warn, mobile)
    if mobile is not None:
        _log_room_histograms(rec, log, tree, points)
    # A mobile manipulator perceives both ways: rooms and scans, and objects.
    if perception and (mobile is None or len(log.base_t)):
        _log_perception(rec, log, tree, points, warn)


def _log_poi(rec: rr.RecordingStream, log: Log, mobile: MobileView | None) -> None:
    """The POI: path taken (static), moving point, coordinates and speed over time; a
    mobile manipulator's hand in the world (its base's path is drawn by log_base)."""
    import rerun as rr

    if not len(log.poi_t):
        return
    world = hand_track(log)
    radius = 0.004 if mobile is None else 0.015
    path = rr.LineStrips3D([world[:, :3]], colors=[PATH_RGB], radii=radius)
    rec.log("/world/poi/path", path, static=True)
    n = len(log.poi_t)
    times = [rr.TimeColumn(TIMELINE, duration=log.poi_t)]
    rec.send_columns(
        "/world/poi",
        indexes=times,
        columns=rr.Points3D.columns(
            positions=world[:, :3], radii=np.full(n, 0.01), colors=np.tile(HIGHLIGHT, (n, 1))
        ),
    )
    for i, axis in enumerate(("x", "y", "z", "yaw")):
        rec.send_columns(
            f"/signals/poi/{axis}",
            indexes=times,
            columns=rr.Scalars.columns(scalars=log.poi[:, i]),
        )
    if n > 1:
        dt = np.diff(log.poi_t)
        step = np.linalg.norm(np.diff(world[:, :3], axis=0), axis=1)
        speed = step / np.where(dt > 0, dt, np.inf)
        rec.send_columns(
            "/signals/poi/speed",
            indexes=[rr.TimeColumn(TIMELINE, duration=log.poi_t[1:])],
            columns=rr.Scalars.columns(scalars=speed),
        )


def _log_weight_and_gripper(rec: rr.RecordingStream, log: Log) -> None:
    """The scale's weight and the commanded gripper as scalars over time."""
    import rerun as rr

    if len(log.weight_t):
        rec.send_columns(
            "/signals/weight",
            indexes=[rr.TimeColumn(TIMELINE, duration=log.weight_t)],
            columns=rr.Scalars.columns(scalars=log.weight),
        )
    if log.commands:
        ct = np.array([c.t for c in log.commands])
        rec.send_columns(
            "/signals/gripper",
            indexes=[rr.TimeColumn(TIMELINE, duration=ct)],
            columns=rr.Scalars.columns(scalars=[c.gripper for c in log.commands]),
        )


def _log_recorded_clouds(rec: rr.RecordingStream, log: Log) -> None:
    """The point clouds the log recorded, subsampled (:data:`MAX_CLOUD_POINTS`)."""
    import rerun as rr

    for pc in log.point_clouds:
        rec.set_time(TIMELINE, duration=pc.t)
        pts, cols = _subsample(np.asarray(pc.points), pc.colors)
        rec.log("/world/perception/points", rr.Points3D(pts, colors=cols, radii=0.002))


def _log_marks_and_fragments(
    rec: rr.RecordingStream, log: Log, points: Sequence[tuple[float, float, str]]
) -> None:
    """One TextLog per saliency mark and, for a demonstration, per fragment."""
    import rerun as rr

    for m in log.marks:
        rec.set_time(TIMELINE, duration=m.t)
        rec.log(
            "/events/saliency",
            rr.TextLog(
                f"saliency mark ({m.source}) {m.label}".strip(), level="INFO", color=HIGHLIGHT
            ),
        )
    if not log.decisions:
        for t0, t1, label in points:
            rec.set_time(TIMELINE, duration=t0)
            rec.log("/events/fragments", rr.TextLog(f"{label}: {t0:.2f}-{t1:.2f} s", level="DEBUG"))


def _subsample(
    points: np.ndarray, colors: np.ndarray | None, n: int = MAX_CLOUD_POINTS
) -> tuple[np.ndarray, np.ndarray | None]:
    if len(points) <= n:
        return points, colors
    idx = np.random.default_rng(0).choice(len(points), n, replace=False)
    idx.sort()
    return points[idx], None if colors is None else np.asarray(colors)[idx]


def _log_camera(rec: rr.RecordingStream, log: Log) -> None:
    import rerun as rr

    if not log.frames:
        return
    f0 = log.frames[0]
    moving = any(not np.allclose(f.T_world_camera, f0.T_world_camera) for f in log.frames)
    h, w = f0.depth.shape

    def pose(f: CameraFrame) -> rr.Transform3D:
        return rr.Transform3D(translation=f.T_world_camera[:3, 3], mat3x3=f.T_world_camera[:3, :3])

    rec.log(
        "/world/camera",
        rr.Pinhole(
            image_from_camera=f0.K,
            resolution=[w, h],
            camera_xyz=rr.ViewCoordinates.RDF,
            image_plane_distance=0.15,
        ),
        static=True,
    )
    if not moving:
        rec.log("/world/camera", pose(f0), static=True)
    for f in log.frames:
        rec.set_time(TIMELINE, duration=f.t)
        if moving:
            rec.log("/world/camera", pose(f))
        rec.log("/world/camera/image", rr.Image(f.rgb).compress(jpeg_quality=85))
        depth = np.nan_to_num(np.asarray(f.depth, dtype=np.float32), posinf=0.0, neginf=0.0)
        mm = np.clip(depth * 1000.0, 0, 65535).astype(np.uint16)
        rec.log("/world/camera/depth", rr.DepthImage(mm, meter=1000.0, colormap="turbo"))


def _log_decisions(
    rec: rr.RecordingStream,
    log: Log,
    tree: Tree,
    warn: Callable[[str], None],
    mobile: MobileView | None = None,
) -> None:
    """Replay decisions: a TextLog each, distances (and a base's D_P terms) as scalars,
    mapped goal (a base's also as an arrow, with the lidar's pose) and planned path."""
    import rerun as rr

    edges = {e.id: e for e in tree.edges}
    colours = branch_colours(tree)
    name = Path(log.path).name
    for d in log.decisions:
        t = float(d["t"])
        rec.set_time(TIMELINE, duration=t)
        parts = _log_candidates(rec, d.get("candidates") or [])
        chosen = d.get("chosen")
        text = f"node {d.get('node')}: chose {chosen if chosen is not None else 'none'} | " + (
            "; ".join(parts) or "no candidates"
        )
        rec.log("/events/decisions", rr.TextLog(text, level="INFO" if chosen else "WARN"))
        lidar = d.get("lidar_pose")
        if mobile is not None and lidar is not None:
            rec.log(
                "/world/decisions/lidar",
                rr.Arrows3D(
                    **pose_arrows(np.asarray(lidar, dtype=float), mobile.lidar_z),
                    colors=[SCAN_RGB],
                    radii=0.02,
                    labels=[f"lidar at {d.get('node')}"],
                ),
            )
        goal = d.get("mapped_goal")
        if chosen is None or goal is None:
            rec.log("/world/decisions/goal", rr.Clear(recursive=False))
            rec.log("/world/decisions/planned", rr.Clear(recursive=False))
            continue
        colour = colours.get(str(chosen), HIGHLIGHT)
        goal = np.asarray(goal, dtype=float)
        _log_goal(rec, goal, str(chosen), colour, mobile)
        edge = edges.get(str(chosen))
        if edge is None:
            warn(f"{name}: decision at t={t:.2f} s chose {chosen}, not an edge of this tree")
            continue
        duration = float(d.get("duration") or edge.smc.action.dmp.duration)
        _log_planned(rec, log, edge, t, goal, duration, colour, mobile)


def _log_candidates(rec: rr.RecordingStream, candidates: Sequence[dict]) -> list[str]:
    """Each candidate's D_P and (a base's) D_P terms as scalars; returns their words
    (``e3 d_p=0.012 (room 0.010, scan 0.002) contingent``) for the decision's TextLog."""
    import rerun as rr

    parts = []
    for c in candidates:
        dp = c.get("d_p")
        raw = c.get("terms") or {}
        order = [k for k in _TERMS if k in raw] + sorted(k for k in raw if k not in _TERMS)
        terms = {k: raw[k] for k in order if raw[k] is not None}
        parts.append(
            f"{c.get('edge')} d_p={'-' if dp is None else f'{dp:.3f}'}"
            + (f" ({', '.join(f'{k} {v:.3f}' for k, v in terms.items())})" if terms else "")
            + f"{' contingent' if c.get('contingent') else ''}"
        )
        if dp is not None:
            rec.log(f"/signals/decision/d_p/{c.get('edge')}", rr.Scalars(float(dp)))
        for k, v in terms.items():
            rec.log(f"/signals/decision/{k}/{c.get('edge')}", rr.Scalars(float(v)))
    return parts


def _log_goal(
    rec: rr.RecordingStream,
    goal: np.ndarray,
    chosen: str,
    colour: Rgb,
    mobile: MobileView | None,
) -> None:
    """The chosen SMC's mapped goal as a point (a base's ``[x, y, z, yaw]`` also as an
    arrow)."""
    import rerun as rr

    point = rr.Points3D(
        [goal[:3]],
        colors=[colour],
        radii=0.012 if mobile is None else 0.04,
        labels=[f"goal of {chosen}"],
    )
    if mobile is not None and len(goal) == 4:
        arrow = rr.Arrows3D(**pose_arrows(goal[[0, 1, 3]], 0.02), colors=[colour], radii=0.03)
        rec.log("/world/decisions/goal", point, arrow)
    else:
        rec.log("/world/decisions/goal", point)


def _log_planned(
    rec: rr.RecordingStream,
    log: Log,
    edge: Edge,
    t: float,
    goal: np.ndarray,
    duration: float,
    colour: Rgb,
    mobile: MobileView | None,
) -> None:
    """The path ``edge``'s DMP plans from the POI at ``t`` (a mobile manipulator's drive:
    from its base) to the mapped ``goal``; nothing when the start is unknown or the goal's
    shape is not the DMP's."""
    import rerun as rr

    from smccli.learn.dmp import rollout

    start = _poi_at(log, t)
    if edge.smc.action.poi == "base" and len(log.base_t):
        bt, base = base_track(log)  # a mobile manipulator's drive starts at its base
        start = base[int(np.argmin(np.abs(bt - t)))]
    if start is None or goal.shape != edge.smc.action.dmp.start.shape:
        return
    _, y = rollout(edge.smc.action.dmp, start=start, goal=goal, duration=duration)
    radius = 0.006 if mobile is None else 0.02
    label = f"{edge.id} planned"
    planned = rr.LineStrips3D([y[:, :3]], colors=[colour], radii=radius, labels=[label])
    rec.log("/world/decisions/planned", planned)


def _log_perception(
    rec: rr.RecordingStream,
    log: Log,
    tree: Tree,
    points: Sequence[tuple[float, float, str]],
    warn: Callable[[str], None],
) -> None:
    """Point cloud, clusters and the salient cluster recomputed at each decision point."""
    import rerun as rr

    from smccli.perception import cloud_from_frame, clusters_from_frame, salient_cluster

    name = Path(log.path).name
    if not log.frames or not points:
        return
    robot = None
    try:
        from smccli.logs.robot import geometry_at, robot_model_of

        if log.joint_states:
            robot = robot_model_of(log)
    except (SmcError, ValueError, KeyError, Exception) as exc:  # noqa: B014
        warn(f"{name}: no self-filter for the point clouds ({str(exc).splitlines()[0]})")
    pp = tree.params.perception
    for k, (t0, t1, label) in enumerate(points):
        frame = _frame_at(log.frames, t0)
        geom = geometry_at(robot, log, frame.t) if robot is not None else None
        base = None
        if len(log.base_t):  # a mobile manipulator's crop box rides its base
            base = log.base[int(np.argmin(np.abs(log.base_t - frame.t)))]
        try:
            pts, cols = cloud_from_frame(frame, geom, pp, base=base)
            clusters = clusters_from_frame(frame, geom, pp, base)
        except (ValueError, RuntimeError, LogError) as exc:
            warn(f"{name}: perception failed at t={t0:.2f} s ({str(exc).splitlines()[0]})")
            continue
        rec.set_time(TIMELINE, duration=t0)
        shown, shown_cols = _subsample(pts, cols)
        rec.log("/world/decisions/cloud", rr.Points3D(shown, colors=shown_cols, radii=0.0015))
        if clusters:
            rec.log(
                "/world/decisions/clusters",
                cluster_boxes(
                    clusters,
                    [cluster_rgb(c, tree) for c in clusters],
                    [f"{cluster_name(c, tree)} #{i}" for i, c in enumerate(clusters)],
                    0.002,
                ),
            )
        else:
            rec.log("/world/decisions/clusters", rr.Clear(recursive=False))
        idx = None
        if log.decisions and k < len(log.decisions):
            d = log.decisions[k]
            chosen = [c for c in d.get("candidates") or [] if c.get("edge") == d.get("chosen")]
            if chosen and isinstance(chosen[0].get("cluster"), int):
                idx = chosen[0]["cluster"] if chosen[0]["cluster"] < len(clusters) else None
        if idx is None:
            poi_end = _poi_at(log, t1)
            if poi_end is not None:
                idx = salient_cluster(clusters, poi_end[:3], tree.params.epsilon)
        if idx is None:
            rec.log("/world/decisions/salient", rr.Clear(recursive=False))
            text = f"{label}: {len(clusters)} cluster(s), none salient"
        else:
            c = clusters[idx]
            rec.log(
                "/world/decisions/salient",
                cluster_boxes(
                    [c], [HIGHLIGHT], [f"salient: {cluster_name(c, tree)} #{idx}"], 0.005
                ),
            )
            text = f"{label}: {len(clusters)} cluster(s), salient #{idx} {cluster_name(c, tree)}"
        rec.log("/events/perception", rr.TextLog(text, level="DEBUG"))


def _log_room_histograms(
    rec: rr.RecordingStream, log: Log, tree: Tree, points: Sequence[tuple[float, float, str]]
) -> None:
    """At each decision point: the camera's whole-frame colour histogram, the one stored in
    the SMC chosen there (replay) or compiled from there (demonstration), and a line."""
    import rerun as rr

    from smccli.perception.room import d_room, room_histogram

    if not log.frames:
        return
    pp = tree.params.perception
    edges = {e.id: e for e in tree.edges}
    for k, (t0, _t1, label) in enumerate(points):
        frame = _frame_at(log.frames, t0)
        hist = room_histogram(frame.rgb, pp)
        rgb = hist_rgb(hist, tree)
        edge = None
        if log.decisions:
            if k < len(log.decisions):
                edge = edges.get(str(log.decisions[k].get("chosen")))
        else:
            edge = next(
                (
                    e
                    for e in tree.edges
                    if any(s.sha256 == log.sha256 and abs(s.t0 - t0) < 0.05 for s in e.sources)
                ),
                None,
            )
        rec.set_time(TIMELINE, duration=t0)
        rec.log("/signals/room_histogram/camera", rr.BarChart(hist, color=rgb))
        text = f"{label}: room mostly {colour_name(rgb)} (camera at t={frame.t:.2f} s)"
        if edge is None or edge.smc.perception.room is None:
            rec.log("/signals/room_histogram/smc", rr.Clear(recursive=False))
        else:
            stored = edge.smc.perception.room
            srgb = hist_rgb(stored, tree)
            rec.log("/signals/room_histogram/smc", rr.BarChart(np.asarray(stored), color=srgb))
            text += (
                f"; {edge.id} stored a room mostly {colour_name(srgb)}, "
                f"d_room {d_room(hist, np.asarray(stored), pp):.3f}"
            )
        rec.log("/events/perception", rr.TextLog(text, level="DEBUG"))
