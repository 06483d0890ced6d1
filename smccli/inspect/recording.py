"""``smc inspect``: a tree and its logs as Rerun recordings (DESIGN.md section 6).

One recording per log (a tree alone: one recording), all in application ``smc``; each
holds the tree (static) and the log on the timeline ``time`` (simulation seconds):

- ``/tree``: the tree as a graph, one GraphNodes node per decision point and one
  GraphEdges edge per SMC; ``/tree/labels``: one labelled node per SMC at its edge's
  midpoint, coloured with its salient object's dominant colour (salient perceptions,
  gripper event, support, sources); ``/tree/smcs``: the same as a Markdown table.
- ``/world/actions/<edge>``: each SMC's DMP rolled out at its demonstrated start and goal
  (world frame), coloured by branch; ``.../goal`` its goal, ``.../object`` its salient object.
- ``/world/poi``: the POI (moving point) and ``/world/poi/path`` the path taken;
  ``/world/camera``: pose, pinhole, ``image`` and ``depth``; ``/world/decisions/*``: point
  cloud, clusters and the salient one recomputed at each decision point, and for replays
  the mapped goal and the planned path; ``/world/perception/points``: recorded clouds.
- ``/signals/...``: weight, gripper command, POI coordinates and speed, replay distances.
- ``/events/saliency`` (one TextLog per saliency mark), ``/events/fragments``,
  ``/events/decisions`` (one per ``/smc/decision`` record), ``/events/perception``.

A mobile base (a tree with room / scan perceptions, or a log with ``/lidar/scan``) adds:

- ``/world/rooms``: the scene's regions as closed line strips on the floor, labelled with
  their names, and ``/world/places`` its named places as arrows (static, if it has any).
- ``/world/actions/<edge>/scan``: the SMC's stored scan drawn in the world at its
  ``scan_pose``, ``.../scan_pose`` that pose and ``.../goal_pose`` the goal in the world
  (a scan-frame goal composed with ``scan_pose``), as arrows; ``/tree/labels`` say "room
  mostly <colour>, scan at (x, y)" and take the room histogram's dominant colour.
- ``/world/lidar/scan``: each scan's returns in the world (placed by the lidar's odometry
  pose: the POI composed with the lidar's mounting; scans thinned in time to at most
  ``MAX_SCAN_POINTS`` points), ``/world/lidar/pose`` the lidar's pose as an arrow.
- ``/world/base``: the base's footprint as a box, ``/world/base/heading`` its heading
  (the path taken is ``/world/poi/path``, on the floor).
- ``/signals/room_histogram/camera``: the camera's whole-frame colour histogram at each
  decision point (BarChart), ``/signals/room_histogram/smc`` the histogram stored in the
  SMC chosen there (replay) or compiled from there (demonstration).
- ``/signals/decision/<term>/<edge>``: a replay's D_P terms per candidate (``room``,
  ``scan``, ``icp_fitness``), also in ``/events/decisions``; ``/world/decisions/goal`` the
  mapped goal as a point and an arrow, ``/world/decisions/lidar`` the lidar's pose there.

A base's decision points show their room histogram instead of the camera's point cloud and
object clusters (``/world/decisions/cloud``, ``clusters`` and ``salient`` are left out).

Rerun is imported only here. ``--serve`` runs the ``rerun`` binary shipped with
rerun-sdk (the Python API binds every interface; the binary takes ``--bind``).
"""

from __future__ import annotations

import math
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
import urllib.parse
import urllib.request
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from smccli.errors import LogError, SmcError
from smccli.inspect.robot_view import log_robot
from smccli.inspect.views import (
    TIMELINE,
    Framing,
    blueprint,
    floor_framing,
    graph_layout,
    workspace_framing,
)
from smccli.learn.tree import ROOT, Edge, Tree, load_tree
from smccli.logs.ros2_bag import TopicMap
from smccli.outputs import check_output
from smccli.perception.colours import colour_name, dominant_rgb

APP_ID = "smc"
MAX_CLOUD_POINTS = 40_000
"""Point clouds are subsampled to at most this many points (viewer and file size)."""
MAX_SCAN_POINTS = 100_000
"""A log's lidar scans are thinned in time to at most this many returns in all (every
scan of a 26 s log at 10 Hz, 360 beams, fits)."""

_PALETTE = [
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
]
_HIGHLIGHT = (255, 215, 0)
_TEXT = (118, 118, 118)
"""Graph text: contrast about 4.5:1 on both the light and the dark theme."""
_SWATCH = "\u25a0"
"""A swatch in the graph: a square in the object's colour."""
_PATH = (128, 128, 128)
"""The path a log took (neutral: the branch colours are the demonstrated actions')."""


@dataclass(frozen=True, slots=True)
class InspectResult:
    """What ``inspect`` produced."""

    recordings: tuple[str, ...]
    """Recording ids, one per log (``tree`` when no log was given)."""
    rrd: Path | None
    """The .rrd written (``--save``), else None."""
    url: str | None = None
    """The web viewer's address (``--serve``), else None."""
    warnings: tuple[str, ...] = field(default_factory=tuple)
    """One-line warnings (log without joint states, unknown edge in a decision...)."""


# --- public entry ---------------------------------------------------------------------


def inspect(
    tree_path: Path,
    logs: Sequence[Path] = (),
    *,
    save: Path | None = None,
    spawn: bool = False,
    serve: bool = False,
    port: int = 9090,
    grpc_port: int | None = None,
    force: bool = False,
    on_warning: Callable[[str], None] | None = None,
    on_message: Callable[[str], None] | None = None,
    topic_map: TopicMap | None = None,
) -> InspectResult:
    """Show ``tree_path`` and ``logs`` in Rerun: write ``save`` (.rrd), spawn or serve a viewer.
    With ``topic_map`` the logs are ROS 2 bags read through it.

    The output is checked first (its folder exists and is writable; an existing file needs
    ``force``), then inputs are all read and checked: a missing or corrupt tree or log raises
    TreeError / LogError (one line naming the file) before anything is written.
    ``serve`` blocks until Ctrl-C, then stops the viewer it started (see :func:`serve_recordings`);
    ``on_message`` hears the addresses it serves at.
    """
    if sum([save is not None, spawn, serve]) != 1:
        raise SmcError("inspect: choose exactly one of --save, --spawn, --serve")
    warnings: list[str] = []

    def warn(msg: str) -> None:
        warnings.append(msg)
        if on_warning is not None:
            on_warning(msg)

    if save is not None:
        check_output(save, force=force)
    tree = load_tree(Path(tree_path))
    from smccli.logs import read_log
    from smccli.logs.ros2_bag import read_ros2_bag

    loaded = [
        read_log(Path(p), on_warning=warn)
        if topic_map is None
        else read_ros2_bag(Path(p), topic_map, on_warning=warn)
        for p in logs
    ]
    for log in loaded:
        _warn_missing_topics(log, warn)
    if serve:
        addresses = serve_recordings(
            tree,
            loaded,
            port=port,
            grpc_port=grpc_port,
            tree_name=Path(tree_path).name,
            warn=warn,
            on_message=on_message,
        )
        ids = [rid for rid, _ in _recording_plan(tree, loaded, Path(tree_path).name)]
        return InspectResult(tuple(ids), None, addresses.viewer, tuple(warnings))
    if spawn:
        ids = spawn_viewer(tree, loaded, tree_name=Path(tree_path).name, warn=warn)
        return InspectResult(tuple(ids), None, None, tuple(warnings))
    assert save is not None
    ids = write_rrd(tree, loaded, Path(save), tree_name=Path(tree_path).name, warn=warn)
    return InspectResult(tuple(ids), Path(save), None, tuple(warnings))


def _warn_missing_topics(log: Any, warn: Callable[[str], None]) -> None:
    """A viewer shows what a log holds: a topic compile would need and the log lacks is a
    warning naming it, not an error (``smc compile`` and ``smc doctor`` refuse such a log)."""
    from smccli.learn.compile import required_topics

    missing = sorted(t for t in required_topics(log) if log.topic_counts.get(t, 0) == 0)
    if missing:
        warn(f"{log.path}: no {', '.join(missing)}: shown without (compile would refuse it)")


# --- recordings -------------------------------------------------------------------------


def _recording_plan(tree: Tree, logs: Sequence[Any], tree_name: str) -> list[tuple[str, Any]]:
    """(recording id, log or None) pairs: one per log, or one for the tree alone."""
    if not logs:
        return [(f"{Path(tree_name).stem}", None)]
    seen: dict[str, int] = {}
    plan = []
    for log in logs:
        rid = Path(log.path).stem
        seen[rid] = seen.get(rid, 0) + 1
        plan.append((rid if seen[rid] == 1 else f"{rid}-{seen[rid]}", log))
    return plan


def _blueprint_for(tree: Tree, logs: Sequence[Any]) -> Any:
    """The blueprint with the graph fitted to this tree and the 3D view on its workspace."""
    labels = {e.id: edge_label(e, tree) for e in tree.edges}
    return blueprint(
        mobile=_is_mobile(tree, logs),
        graph=graph_layout(tree, labels),
        framing=framing(tree, logs),
    )


def framing(tree: Tree, logs: Sequence[Any]) -> Framing:
    """Where the 3D view opens: an arm's perception crop (the workspace), a mobile base's
    rooms (from the first log's scene, else the tree's), else the paths the logs took."""
    if _is_mobile(tree, logs):
        mobile = mobile_view(tree, logs[0] if logs else None)
        rects = [r for _, rs in (mobile.regions if mobile else ()) for r in rs]
        if rects:
            r = np.array(rects)
            return floor_framing(
                np.array([r[:, 0].min(), r[:, 2].min()]), np.array([r[:, 1].max(), r[:, 3].max()])
            )
        paths = [log.poi[:, :2] for log in logs if len(log.poi_t)]
        if paths:
            xy = np.concatenate(paths)
            return floor_framing(xy.min(axis=0) - 1.0, xy.max(axis=0) + 1.0)
        return floor_framing(np.array([-3.0, -3.0]), np.array([3.0, 3.0]))
    p = tree.params.perception
    return workspace_framing(np.array(p.crop_min), np.array(p.crop_max))


def _fill(rec: Any, tree: Tree, log: Any, warn: Callable[[str], None]) -> None:
    mobile = mobile_view(tree, log, warn)
    log_tree(rec, tree, mobile=mobile)
    if log is not None:
        log_log(rec, log, tree, warn=warn, mobile=mobile)


def write_rrd(
    tree: Tree,
    logs: Sequence[Any],
    out: Path,
    *,
    tree_name: str = "tree.json",
    warn: Callable[[str], None] = lambda m: None,
) -> list[str]:
    """Write one .rrd holding a recording per log (the tree in each); returns their ids."""
    import rerun as rr

    out = check_output(out, force=True)  # overwriting was the caller's decision
    plan = _recording_plan(tree, logs, tree_name)
    bp = _blueprint_for(tree, logs)
    with tempfile.TemporaryDirectory(prefix="smc-rrd-", dir=out.parent) as tmp:
        parts = []
        for k, (rid, log) in enumerate(plan):
            part = Path(tmp) / f"{k}.rrd"
            rec = rr.RecordingStream(APP_ID, recording_id=rid)
            rec.save(part, default_blueprint=bp)
            rec.send_recording_name(rid)
            _fill(rec, tree, log, warn)
            rec.flush()
            rec.disconnect()
            parts.append(part)
        staged = Path(tmp) / "out.rrd"
        if len(parts) == 1:
            shutil.move(parts[0], staged)
        else:
            # A Python stream writes one recording per file (files with footers cannot be
            # concatenated); the rerun binary merges them and keeps the recordings apart.
            proc = subprocess.run(
                [rerun_binary(), "rrd", "merge", *map(str, parts), "-o", str(staged)],
                capture_output=True,
                text=True,
            )
            if proc.returncode != 0 or not staged.is_file():
                last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
                raise SmcError(f"{out}: rerun rrd merge failed ({last})")
        os.replace(staged, out)
    return [rid for rid, _ in plan]


def spawn_viewer(
    tree: Tree,
    logs: Sequence[Any],
    *,
    tree_name: str = "tree.json",
    warn: Callable[[str], None] = lambda m: None,
) -> list[str]:
    """Send the recordings to a native viewer (spawned if none listens on 9876)."""
    import rerun as rr

    plan = _recording_plan(tree, logs, tree_name)
    bp = _blueprint_for(tree, logs)
    for rid, log in plan:
        rec = rr.RecordingStream(APP_ID, recording_id=rid)
        try:
            rec.spawn(default_blueprint=bp)
        except Exception as exc:  # no display, no viewer binary
            raise SmcError(
                f"--spawn: cannot start Rerun's viewer ({exc}); use --save or --serve"
            ) from None
        rec.send_recording_name(rid)
        _fill(rec, tree, log, warn)
        rec.flush()
    return [rid for rid, _ in plan]


# --- serving ------------------------------------------------------------------------------


def rerun_binary() -> str:
    """Path of the ``rerun`` executable shipped with rerun-sdk (or ``RERUN_CLI_PATH``)."""
    if os.environ.get("RERUN_CLI_PATH"):
        return os.environ["RERUN_CLI_PATH"]
    import rerun_cli

    exe = Path(rerun_cli.__file__).parent / "rerun"
    if not exe.is_file():
        found = shutil.which("rerun")
        if found is None:
            raise SmcError(f"rerun binary not found at {exe} nor on PATH (reinstall rerun-sdk)")
        return found
    return str(exe)


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _port_taken(port: int) -> bool:
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return True
    return False


def _stop(proc: subprocess.Popen[bytes]) -> None:
    """Stop ``proc`` and its process group: SIGTERM, then SIGKILL after 5 s."""
    if proc.poll() is not None:
        return
    for sig, wait in ((signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(wait)
            break
        except subprocess.TimeoutExpired:
            continue


@dataclass(frozen=True, slots=True)
class Addresses:
    """Where ``--serve`` serves (both on 127.0.0.1)."""

    viewer: str
    """The web viewer's page, with the data address in its query: open this."""
    data: str
    """The gRPC proxy the page reads the recordings from (forward its port too)."""


def serve_recordings(
    tree: Tree,
    logs: Sequence[Any],
    *,
    port: int,
    grpc_port: int | None = None,
    tree_name: str = "tree.json",
    warn: Callable[[str], None] = lambda m: None,
    on_message: Callable[[str], None] | None = None,
    ready_timeout: float = 60.0,
    until: Callable[[], bool] | None = None,
) -> Addresses:
    """Serve the recordings with Rerun's web viewer on 127.0.0.1:``port`` (data on
    ``grpc_port``, a free port if None) until Ctrl-C (or ``until()``).

    The recordings are sent to the viewer's gRPC proxy one after the other, the first log's
    last: the viewer selects each recording as it arrives, so the page opens on the first
    log's (the tree's when there is no log), whatever the timing. ``on_message`` hears the
    two addresses once everything is sent; on Ctrl-C the viewer process (and its group) is
    stopped.
    """
    import rerun as rr

    for flag, p in (("--port", port), ("--grpc-port", grpc_port)):
        if p is None:
            continue
        if not 0 < p < 65536:
            raise SmcError(f"{flag} {p}: expected 1-65535")
        if _port_taken(p):
            raise SmcError(f"{flag} {p}: 127.0.0.1:{p} is already in use")
    if grpc_port == port:
        raise SmcError(f"--grpc-port {grpc_port}: the same as --port")
    grpc = grpc_port if grpc_port is not None else free_port()
    addresses = Addresses(
        viewer=f"http://127.0.0.1:{port}/?url="
        + urllib.parse.quote(f"rerun+http://127.0.0.1:{grpc}/proxy", safe=""),
        data=f"rerun+http://127.0.0.1:{grpc}/proxy",
    )
    cmd = [
        rerun_binary(),
        "--serve-web",
        "--bind",
        "127.0.0.1",
        "--port",
        str(grpc),
        "--web-viewer-port",
        str(port),
    ]
    # Ctrl-C must reach us: a shell's `cmd &` may start us with SIGINT ignored.
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    with tempfile.TemporaryDirectory(prefix="smc-serve-") as tmp:
        log_path = Path(tmp) / "viewer.log"
        with open(log_path, "wb") as viewer_log:
            proc = subprocess.Popen(
                cmd,
                stdin=subprocess.DEVNULL,
                stdout=viewer_log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
            try:
                _wait_ready(proc, log_path, port, grpc, ready_timeout)
                bp = _blueprint_for(tree, logs)
                for rid, log in reversed(_recording_plan(tree, logs, tree_name)):
                    rec = rr.RecordingStream(APP_ID, recording_id=rid)
                    rec.connect_grpc(addresses.data, default_blueprint=bp)
                    rec.send_recording_name(rid)
                    _fill(rec, tree, log, warn)
                    rec.flush()
                    rec.disconnect()
                if on_message is not None:
                    on_message(f"viewer: {addresses.viewer}")
                    on_message(f"data:   {addresses.data}")
                    on_message(
                        f"(over SSH: ssh -L {port}:127.0.0.1:{port} -L {grpc}:127.0.0.1:{grpc}"
                        " HOST; Ctrl-C to stop)"
                    )
                while proc.poll() is None and not (until is not None and until()):
                    time.sleep(0.2)
                if proc.returncode not in (None, 0):
                    raise SmcError(f"rerun web viewer exited with code {proc.returncode}")
            except KeyboardInterrupt:
                if on_message is not None:
                    on_message("stopping the web viewer")
            finally:
                _stop(proc)
                signal.signal(signal.SIGINT, old)
    return addresses


def _wait_ready(
    proc: subprocess.Popen[bytes], log_path: Path, port: int, grpc: int, timeout: float
) -> None:
    """Wait until the viewer's page answers and its gRPC port accepts connections."""
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + timeout
    while True:
        if proc.poll() is not None:
            tail = log_path.read_text(errors="replace").strip().splitlines()
            raise SmcError(
                f"rerun web viewer exited with code {proc.returncode}"
                f" ({tail[-1] if tail else 'no output'})"
            )
        try:
            with urllib.request.urlopen(url, timeout=1.0):
                pass
            with socket.create_connection(("127.0.0.1", grpc), timeout=1.0):
                return
        except OSError:
            if time.monotonic() > deadline:
                raise SmcError(
                    f"rerun web viewer did not answer on {url} within {timeout:.0f} s"
                ) from None
            time.sleep(0.2)


# --- colours and labels -----------------------------------------------------------------


def _cluster_rgb(cluster: Any, tree: Tree) -> tuple[int, int, int]:
    p = tree.params.perception
    return dominant_rgb(cluster.histogram, p.hue_bins, p.sat_bins, p.val_bins)


def _cluster_name(cluster: Any, tree: Tree) -> str:
    return colour_name(_cluster_rgb(cluster, tree))


def swatch_rgb(edge: Edge, tree: Tree, fallback: tuple[int, int, int]) -> tuple[int, int, int]:
    """An SMC's colour in the graph: its salient object's, else its room's, else its branch's."""
    p = edge.smc.perception
    if p.cluster is not None:
        return _cluster_rgb(p.cluster, tree)
    if p.room is not None:
        return _hist_rgb(p.room, tree)
    return fallback


def _hist_rgb(histogram: Any, tree: Tree) -> tuple[int, int, int]:
    """Dominant colour of a colour histogram (a room's, binned as the clusters')."""
    p = tree.params.perception
    return dominant_rgb(np.asarray(histogram), p.hue_bins, p.sat_bins, p.val_bins)


def _sources_text(edge: Edge, limit: int = 3) -> str:
    parts = [f"{s.log} {s.t0:.1f}-{s.t1:.1f} s" for s in edge.sources[:limit]]
    if len(edge.sources) > limit:
        parts.append(f"+{len(edge.sources) - limit} more")
    return "; ".join(parts)


def perception_text(edge: Edge, tree: Tree) -> str:
    """Salient perceptions of an edge in a few words: object colour and size, weight."""
    parts = []
    c = edge.smc.perception.cluster
    if c is not None:
        ext = "x".join(f"{100 * e:.0f}" for e in c.extents)
        parts.append(f"{_cluster_name(c, tree)} object {ext} cm")
    w = edge.smc.perception.weight
    if w is not None:
        parts.append(f"weight {1000 * w:.0f} g")
    p = edge.smc.perception
    if p.room is not None:
        parts.append(f"room mostly {colour_name(_hist_rgb(p.room, tree))}")
    if p.scan is not None and p.scan_pose is not None:
        parts.append(f"scan at ({p.scan_pose[0]:.2f}, {p.scan_pose[1]:.2f})")
    elif p.room is not None:
        parts.append("no salient scan")
    return ", ".join(parts) or "no salient object"


def edge_label(edge: Edge, tree: Tree) -> str:
    """Graph label of an SMC: id, salient perceptions, gripper event, support, sources."""
    return (
        f"{edge.id}: {perception_text(edge, tree)}\n{edge.smc.action.event} · "
        f"support {edge.support}\n{_sources_text(edge, 1)}"
    )


def branch_colours(tree: Tree) -> dict[str, tuple[int, int, int]]:
    """Edge id -> colour: a chain keeps its colour, each child of a fork starts a new one."""
    out: dict[str, tuple[int, int, int]] = {}
    k = 0
    stack: list[tuple[str, tuple[int, int, int] | None]] = [(ROOT, None)]
    while stack:
        node, colour = stack.pop()
        kids = tree.children(node)
        for e in reversed(kids):
            if colour is None or len(kids) > 1:
                c = _PALETTE[k % len(_PALETTE)]
                k += 1
            else:
                c = colour
            out[e.id] = c
            stack.append((e.child, c))
    for e in tree.edges:  # unreachable edges (should not exist): still coloured
        out.setdefault(e.id, _PALETTE[7])
    return out


# --- a mobile base ------------------------------------------------------------------------


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
_SCAN_RGB = (230, 70, 50)
_TERMS = ("room", "scan", "icp_fitness")
"""A base's D_P terms in a decision record, in the order they are shown."""


def _tree_is_mobile(tree: Tree) -> bool:
    return any(
        e.smc.perception.room is not None
        or e.smc.perception.scan is not None
        or e.smc.action.goal_frame == "scan"
        for e in tree.edges
    )


def _is_mobile(tree: Tree, logs: Sequence[Any]) -> bool:
    """Whether the tree or a log is a mobile base's (room / scan perceptions, lidar scans)."""
    return _tree_is_mobile(tree) or any(getattr(log, "scans", None) for log in logs)


def _scene_geometry(scene: Any) -> MobileView:
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
    own = np.flatnonzero(model.geom_group == robot.geom_group)
    if pid >= 0 and len(own) and not robot.arm_joints:
        R = data.site_xmat[pid].reshape(3, 3)
        yaw = math.atan2(R[1, 0], R[0, 0])
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
    tree: Tree, log: Any | None, warn: Callable[[str], None] = lambda m: None
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


def _pose_arrows(poses: np.ndarray, z: float, length: float = _ARROW) -> dict[str, Any]:
    """Arrows3D's ``origins`` and ``vectors`` for planar poses ``[x, y, yaw]``, each of
    shape (N, 3): at height ``z``, ``length`` long along the yaw."""
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    origins = np.column_stack([poses[:, 0], poses[:, 1], np.full(len(poses), z)])
    vectors = np.column_stack(
        [length * np.cos(poses[:, 2]), length * np.sin(poses[:, 2]), np.zeros(len(poses))]
    )
    return {"origins": origins, "vectors": vectors}


def _in_world(points: np.ndarray, pose: np.ndarray, z: float) -> np.ndarray:
    """2-D points in a frame at planar ``pose`` -> (N, 3) world points at height ``z``."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    xy = points @ np.array([[c, s], [-s, c]]) + np.asarray(pose[:2])
    return np.column_stack([xy, np.full(len(xy), z)])


def _goal_pose_world(edge: Edge) -> np.ndarray | None:
    """A base SMC's goal in the world ``[x, y, yaw]``: a scan-frame goal composed with its
    scan pose; a world goal as it is; None for an object-frame goal."""
    from smccli.perception.scan import pose_compose

    a, p = edge.smc.action, edge.smc.perception
    g = np.asarray(a.goal, dtype=float)
    if a.goal_frame == "scan" and p.scan_pose is not None and len(g) == 4:
        return pose_compose(np.asarray(p.scan_pose, dtype=float), g[[0, 1, 3]])
    if a.goal_frame == "world" and len(g) == 4:
        return g[[0, 1, 3]]
    return None


def _log_stored_scan(
    rec: Any, edge: Edge, colour: tuple[int, int, int], mobile: MobileView
) -> None:
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
        rec.log(
            f"{base}/scan_pose",
            rr.Arrows3D(
                **_pose_arrows(pose, mobile.lidar_z),
                colors=[colour],
                radii=0.015,
                labels=[f"{edge.id} scan taken here"],
            ),
            static=True,
        )
    goal = _goal_pose_world(edge)
    if goal is not None:
        rec.log(
            f"{base}/goal_pose",
            rr.Arrows3D(
                **_pose_arrows(goal, 0.02),
                colors=[colour],
                radii=0.025,
                labels=[f"{edge.id} goal ({edge.smc.action.goal_frame} frame)"],
            ),
            static=True,
        )


def _log_rooms(rec: Any, mobile: MobileView) -> None:
    """The scene's rooms as closed outlines on the floor and its places as arrows (static)."""
    import rerun as rr

    strips, colours, labels = [], [], []
    for k, (name, rects) in enumerate(mobile.regions):
        for x0, x1, y0, y1 in rects:
            strips.append([(x0, y0, 0.0), (x1, y0, 0.0), (x1, y1, 0.0), (x0, y1, 0.0)])
            strips[-1].append(strips[-1][0])  # closed
            colours.append(_PALETTE[k % len(_PALETTE)])
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
                **_pose_arrows(poses, 0.01, 0.25),
                colors=[(150, 150, 150)],
                radii=0.01,
                labels=[n for n, _ in mobile.places],
            ),
            static=True,
        )


def _lidar_poses(log: Any, times: np.ndarray, mobile: MobileView) -> np.ndarray:
    """The lidar's planar poses ``[x, y, yaw]`` at ``times``: the POI (odometry)
    interpolated there, composed with the lidar's mounting; shape (N, 3)."""
    from smccli.perception.scan import pose_compose

    bt, base = base_track(log)
    poi = np.column_stack([np.interp(times, bt, base[:, i]) for i in (0, 1, 3)])
    return np.array([pose_compose(p, mobile.mount) for p in poi]).reshape(-1, 3)


def base_track(log: Any) -> tuple[np.ndarray, np.ndarray]:
    """A mobile robot's base over time: (times (T,) [s], poses (T, 4) ``[x, y, 0, yaw]``);
    a mobile manipulator's from ``/robot/base`` (its POI is the hand), else the POI."""
    if len(log.base_t):
        b = log.base
        return log.base_t, np.column_stack([b[:, 0], b[:, 1], np.zeros(len(b)), b[:, 2]])
    return log.poi_t, log.poi


def hand_track(log: Any) -> np.ndarray:
    """The POI in the world over time, shape (T, 4): a mobile manipulator's hand (logged in
    its base's frame) composed with its base's pose, else the POI as logged."""
    if not len(log.base_t):
        return np.asarray(log.poi)
    from smccli.world.sensors import hand_in_world

    idx = np.clip(np.searchsorted(log.base_t, log.poi_t), 0, len(log.base_t) - 1)
    return hand_in_world(log.base[idx], log.poi)


def _log_base(rec: Any, log: Any, mobile: MobileView) -> None:
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
        quats = np.column_stack([np.zeros(n), np.zeros(n), np.sin(yaw / 2), np.cos(yaw / 2)])
        rec.send_columns(
            "/world/base",
            indexes=times,
            columns=rr.Boxes3D.columns(
                centers=centres,
                half_sizes=np.tile([(x1 - x0) / 2, (y1 - y0) / 2, 0.03], (n, 1)),
                quaternions=quats,
                colors=np.tile(_HIGHLIGHT, (n, 1)),
                radii=np.full(n, 0.008),
            ),
        )
    arrows = _pose_arrows(base[:, [0, 1, 3]], 0.07)
    rec.send_columns(
        "/world/base/heading",
        indexes=times,
        columns=rr.Arrows3D.columns(
            **arrows, colors=np.tile(_HIGHLIGHT, (n, 1)), radii=np.full(n, 0.02)
        ),
    )


def _log_scans(rec: Any, log: Any, mobile: MobileView) -> None:
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
            **_pose_arrows(poses, mobile.lidar_z, 0.25),
            colors=np.tile(_SCAN_RGB, (len(t), 1)),
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
            colors=np.tile(_SCAN_RGB, (len(pts), 1)),
            radii=np.full(len(pts), 0.015),
        ).partition(lengths),
    )


def _log_room_histograms(
    rec: Any, log: Any, tree: Tree, points: Sequence[tuple[float, float, str]]
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
        rgb = _hist_rgb(hist, tree)
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
            srgb = _hist_rgb(stored, tree)
            rec.log("/signals/room_histogram/smc", rr.BarChart(np.asarray(stored), color=srgb))
            text += (
                f"; {edge.id} stored a room mostly {colour_name(srgb)}, "
                f"d_room {d_room(hist, np.asarray(stored), pp):.3f}"
            )
        rec.log("/events/perception", rr.TextLog(text, level="DEBUG"))


# --- the tree ---------------------------------------------------------------------------


def _yaw_quat(yaw: float) -> list[float]:
    """Quaternion (x, y, z, w) of a rotation ``yaw`` about world z."""
    return [0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)]


def _boxes(
    clusters: Sequence[Any], colours: Sequence[Any], labels: Sequence[str], radius: float
) -> Any:
    import rerun as rr

    return rr.Boxes3D(
        centers=[c.centroid for c in clusters],
        half_sizes=[np.asarray(c.extents) / 2 for c in clusters],
        quaternions=[rr.Quaternion(xyzw=_yaw_quat(float(c.yaw))) for c in clusters],
        colors=colours,
        labels=labels,
        radii=radius,
    )


def log_tree(rec: Any, tree: Tree, *, mobile: MobileView | None = None) -> None:
    """The tree (static): graph at ``/tree``, actions under ``/world/actions``; for a mobile
    base (``mobile``, see :func:`mobile_view`) also the stored scans, goals and rooms."""
    import rerun as rr

    from smccli.learn.dmp import rollout

    colours = branch_colours(tree)
    labels = {e.id: edge_label(e, tree) for e in tree.edges}
    layout = graph_layout(tree, labels)
    rec.log("/world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    # Text takes its node's colour in Rerun's graph view: one neutral grey that reads on
    # the light and the dark theme; the object's colour goes to a swatch (a coloured
    # square, itself a labelled node) left of the label. One entity: the graph view draws
    # a titled frame around each entity's nodes.
    ids = [*tree.nodes]
    texts = [f"{n} (root)" if n == ROOT else n for n in tree.nodes]
    rgb = [_TEXT] * len(tree.nodes)
    where = [layout.nodes[n] for n in tree.nodes]
    for e in tree.edges:
        ids += [e.id, f"{e.id} colour"]
        texts += [labels[e.id], _SWATCH]
        rgb += [_TEXT, swatch_rgb(e, tree, colours[e.id])]
        where += [layout.labels[e.id], layout.swatches[e.id]]
    rec.log("/tree", rr.GraphNodes(ids, positions=where, labels=texts, colors=rgb), static=True)
    rec.log(
        "/tree",
        rr.GraphEdges([(e.parent, e.child) for e in tree.edges], graph_type="directed"),
        static=True,
    )
    rows = [
        "| edge | parent → child | salient perceptions | event | goal | support | sources |",
        "|---|---|---|---|---|---|---|",
    ]
    for e in tree.edges:
        g = e.smc.action.goal
        goal = f"({g[0]:+.3f}, {g[1]:+.3f}, {g[2]:+.3f}) {e.smc.action.goal_frame}"
        world = _goal_pose_world(e)
        if e.smc.action.goal_frame == "scan" and world is not None:
            goal = (
                f"({g[0]:+.3f}, {g[1]:+.3f}, {math.degrees(g[3]):+.0f}°) scan → world "
                f"({world[0]:+.2f}, {world[1]:+.2f}, {math.degrees(world[2]):+.0f}°)"
            )
        rows.append(
            f"| {e.id} | {e.parent} → {e.child} | {perception_text(e, tree)} | "
            f"{e.smc.action.event} | {goal} | {e.support} | {_sources_text(e, 10)} |"
        )
    scene = tree.scene.get("name", "?")
    head = (
        f"# SMC tree, version {tree.version}\n\nscene {scene}, {len(tree.nodes)} nodes, "
        f"{len(tree.edges)} SMCs\n\n"
    )
    rec.log(
        "/tree/smcs",
        rr.TextDocument(head + "\n".join(rows), media_type="text/markdown"),
        static=True,
    )
    for e in tree.edges:
        dmp = e.smc.action.dmp
        _, y = rollout(dmp, start=dmp.start, goal=dmp.goal)
        base = f"/world/actions/{e.id}"
        rec.log(
            base,
            rr.LineStrips3D(
                [y[:, :3]],
                colors=[colours[e.id]],
                radii=0.005 if mobile is None else 0.02,
                labels=[e.id],
            ),
            static=True,
        )
        if mobile is not None:
            _log_stored_scan(rec, e, colours[e.id], mobile)
        rec.log(
            f"{base}/goal",
            rr.Points3D([dmp.goal[:3]], colors=[colours[e.id]], radii=0.008),
            static=True,
        )
        c = e.smc.perception.cluster
        if c is not None:
            rec.log(
                f"{base}/object",
                _boxes([c], [_cluster_rgb(c, tree)], [f"{e.id}: {_cluster_name(c, tree)}"], 0.001),
                static=True,
            )
    if mobile is not None:
        _log_rooms(rec, mobile)


# --- a log --------------------------------------------------------------------------------


def _frame_at(frames: Sequence[Any], t: float) -> Any:
    if not frames:
        return None
    times = np.array([f.t for f in frames])
    return frames[int(np.argmin(np.abs(times - t)))]


def _poi_at(log: Any, t: float) -> np.ndarray | None:
    """The POI in the world at ``t`` (a mobile manipulator's hand, :func:`hand_track`)."""
    if len(log.poi_t) == 0:
        return None
    k = int(np.argmin(np.abs(log.poi_t - t)))
    return np.asarray(hand_track(log)[k] if len(log.base_t) else log.poi[k])


def decision_points(log: Any, tree: Tree) -> list[tuple[float, float, str]]:
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
    rec: Any,
    log: Any,
    tree: Tree,
    *,
    warn: Callable[[str], None] = lambda m: None,
    perception: bool = True,
    mobile: MobileView | None = None,
) -> None:
    """A demonstration or replay log on the ``time`` timeline (see the module docstring).

    ``mobile``: how to draw a mobile base (default: :func:`mobile_view` of tree and log).
    """
    import rerun as rr

    if mobile is None:
        mobile = mobile_view(tree, log, warn)
    tcol = rr.TimeColumn
    # POI: path taken (static), moving point and coordinates over time; a mobile
    # manipulator's hand in the world (its base's path is drawn by _log_base).
    world = hand_track(log)
    if len(log.poi_t):
        rec.log(
            "/world/poi/path",
            rr.LineStrips3D(
                [world[:, :3]],
                colors=[_PATH],
                radii=0.004 if mobile is None else 0.015,
            ),
            static=True,
        )
        n = len(log.poi_t)
        times = [tcol(TIMELINE, duration=log.poi_t)]
        rec.send_columns(
            "/world/poi",
            indexes=times,
            columns=rr.Points3D.columns(
                positions=world[:, :3], radii=np.full(n, 0.01), colors=np.tile(_HIGHLIGHT, (n, 1))
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
                indexes=[tcol(TIMELINE, duration=log.poi_t[1:])],
                columns=rr.Scalars.columns(scalars=speed),
            )
    if len(log.weight_t):
        rec.send_columns(
            "/signals/weight",
            indexes=[tcol(TIMELINE, duration=log.weight_t)],
            columns=rr.Scalars.columns(scalars=log.weight),
        )
    if log.commands:
        ct = np.array([c.t for c in log.commands])
        rec.send_columns(
            "/signals/gripper",
            indexes=[tcol(TIMELINE, duration=ct)],
            columns=rr.Scalars.columns(scalars=[c.gripper for c in log.commands]),
        )
    _log_camera(rec, log)
    log_robot(rec, log, warn)
    if mobile is not None:
        if len(log.poi_t):
            _log_base(rec, log, mobile)
        _log_scans(rec, log, mobile)
    for pc in log.point_clouds:
        rec.set_time(TIMELINE, duration=pc.t)
        pts, cols = _subsample(np.asarray(pc.points), pc.colors)
        rec.log("/world/perception/points", rr.Points3D(pts, colors=cols, radii=0.002))
    # Events: one TextLog per saliency mark, per fragment, per decision.
    for m in log.marks:
        rec.set_time(TIMELINE, duration=m.t)
        rec.log(
            "/events/saliency",
            rr.TextLog(
                f"saliency mark ({m.source}) {m.label}".strip(), level="INFO", color=_HIGHLIGHT
            ),
        )
    points = decision_points(log, tree)
    if not log.decisions:
        for t0, t1, label in points:
            rec.set_time(TIMELINE, duration=t0)
            rec.log("/events/fragments", rr.TextLog(f"{label}: {t0:.2f}-{t1:.2f} s", level="DEBUG"))
    _log_decisions(rec, log, tree, warn, mobile)
    if mobile is not None:
        _log_room_histograms(rec, log, tree, points)
    # A mobile manipulator perceives both ways: rooms and scans, and objects.
    if perception and (mobile is None or len(log.base_t)):
        _log_perception(rec, log, tree, points, warn)


def _subsample(
    points: np.ndarray, colors: np.ndarray | None, n: int = MAX_CLOUD_POINTS
) -> tuple[np.ndarray, np.ndarray | None]:
    if len(points) <= n:
        return points, colors
    idx = np.random.default_rng(0).choice(len(points), n, replace=False)
    idx.sort()
    return points[idx], None if colors is None else np.asarray(colors)[idx]


def _log_camera(rec: Any, log: Any) -> None:
    import rerun as rr

    if not log.frames:
        return
    f0 = log.frames[0]
    moving = any(not np.allclose(f.T_world_camera, f0.T_world_camera) for f in log.frames)
    h, w = f0.depth.shape

    def pose(f: Any) -> Any:
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
    rec: Any,
    log: Any,
    tree: Tree,
    warn: Callable[[str], None],
    mobile: MobileView | None = None,
) -> None:
    """Replay decisions: a TextLog each, distances (and a base's D_P terms) as scalars,
    mapped goal (a base's also as an arrow, with the lidar's pose) and planned path."""
    import rerun as rr

    from smccli.learn.dmp import rollout

    edges = {e.id: e for e in tree.edges}
    colours = branch_colours(tree)
    name = Path(log.path).name
    for d in log.decisions:
        t = float(d["t"])
        rec.set_time(TIMELINE, duration=t)
        cands = d.get("candidates") or []
        parts = []
        for c in cands:
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
                    **_pose_arrows(np.asarray(lidar, dtype=float), mobile.lidar_z),
                    colors=[_SCAN_RGB],
                    radii=0.02,
                    labels=[f"lidar at {d.get('node')}"],
                ),
            )
        goal = d.get("mapped_goal")
        if chosen is None or goal is None:
            rec.log("/world/decisions/goal", rr.Clear(recursive=False))
            rec.log("/world/decisions/planned", rr.Clear(recursive=False))
            continue
        colour = colours.get(str(chosen), _HIGHLIGHT)
        goal = np.asarray(goal, dtype=float)
        point = rr.Points3D(
            [goal[:3]],
            colors=[colour],
            radii=0.012 if mobile is None else 0.04,
            labels=[f"goal of {chosen}"],
        )
        if mobile is not None and len(goal) == 4:
            arrow = rr.Arrows3D(**_pose_arrows(goal[[0, 1, 3]], 0.02), colors=[colour], radii=0.03)
            rec.log("/world/decisions/goal", point, arrow)
        else:
            rec.log("/world/decisions/goal", point)
        edge = edges.get(str(chosen))
        start = _poi_at(log, t)
        if edge is not None and edge.smc.action.poi == "base" and len(log.base_t):
            bt, base = base_track(log)  # a mobile manipulator's drive starts at its base
            start = base[int(np.argmin(np.abs(bt - t)))]
        if edge is None:
            warn(f"{name}: decision at t={t:.2f} s chose {chosen}, not an edge of this tree")
            continue
        if start is None or goal.shape != edge.smc.action.dmp.start.shape:
            continue
        _, y = rollout(
            edge.smc.action.dmp,
            start=start,
            goal=goal,
            duration=float(d.get("duration") or edge.smc.action.dmp.duration),
        )
        rec.log(
            "/world/decisions/planned",
            rr.LineStrips3D(
                [y[:, :3]],
                colors=[colour],
                radii=0.006 if mobile is None else 0.02,
                labels=[f"{chosen} planned"],
            ),
        )


def _log_perception(
    rec: Any,
    log: Any,
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
                _boxes(
                    clusters,
                    [_cluster_rgb(c, tree) for c in clusters],
                    [f"{_cluster_name(c, tree)} #{i}" for i, c in enumerate(clusters)],
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
                _boxes([c], [_HIGHLIGHT], [f"salient: {_cluster_name(c, tree)} #{idx}"], 0.005),
            )
            text = f"{label}: {len(clusters)} cluster(s), salient #{idx} {_cluster_name(c, tree)}"
        rec.log("/events/perception", rr.TextLog(text, level="DEBUG"))
