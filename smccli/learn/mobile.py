"""A mobile robot's SMCs (paper 4.2, docs/design.md 9): a mobile base's fragments become
navigation SMCs (the room's colours and the salient lidar scan; the base path as a DMP,
its goal in the scan's frame); a mobile manipulator's become SMCs of the hand, the base
or both (two POIs, one duration), the goal in the frame of what the hand goes by."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from smccli.errors import LogError
from smccli.learn import dmp as dmp_mod
from smccli.learn.frames import goal_in_hand, goal_in_object
from smccli.learn.params import SmcParams
from smccli.learn.segmentation import Fragment, fragment_commands
from smccli.learn.smc import (
    Action,
    SalientPerceptions,
    Smc,
    action_from_path,
    action_in_scan_frame,
)
from smccli.logs import Log
from smccli.logs.robot import geometry_at, robot_model_of
from smccli.perception import Cluster, clusters_from_frame, salient_cluster
from smccli.perception.room import room_histogram
from smccli.perception.scan import Scan2D
from smccli.perception.workspace import crop_warnings
from smccli.world.geometry import compose, wrap_yaw
from smccli.world.lidar import RANGE_MAX as LIDAR_RANGE_MAX
from smccli.world.lidar import lidar_mount
from smccli.world.robot_model import RobotModel
from smccli.world.scene import Scene


def base_smcs(
    log: Log, frags: Sequence[Fragment], scene: Scene, params: SmcParams, warnings: list[str]
) -> list[Smc]:
    """The SMCs of a mobile base's fragments (paper 4.2): at each decision point the room's
    colours (SI, eq. 17) and the lidar scan with the lidar's odometry pose (SL, salient by
    eq. 18); the commanded base path as a DMP, its goal in the salient scan's frame."""
    mount = lidar_mount(scene.model(), scene.robot.poi, _lidar_site(log, scene))
    base = log.poi[:, [0, 1, 3]]
    smcs = []
    for k, frag in enumerate(frags):
        cmds = fragment_commands(log, frag)
        t = np.array([c.t for c in cmds]) - cmds[0].t
        path = np.array([c.target for c in cmds], dtype=float)
        smcs.append(
            _navigation_smc(log, k, frag, t, path, log.poi_t, base, mount, params, warnings)
        )
    return smcs


def _lidar_site(log: Log, scene: Scene) -> str:
    lidar = next((m for m in scene.robot.sensors if m.type == "lidar"), None)
    if lidar is None:
        raise LogError(f"{log.path}: robot {scene.robot.name!r} has no lidar; compile needs one")
    return lidar.target


def _navigation_smc(
    log: Log,
    k: int,
    frag: Fragment,
    t: np.ndarray,
    path: np.ndarray,
    base_t: np.ndarray,
    base: np.ndarray,
    mount: np.ndarray,
    params: SmcParams,
    warnings: list[str],
    *,
    poi: str | None = None,
    grip: float = 1.0,
) -> Smc:
    """A fragment that drives the base: the room's colours and the salient scan at its start
    (its lidar pose from odometry ``base`` (B, 3) at times ``base_t``), the base ``path``
    (T, 4) ``[x, y, 0, yaw]`` at times ``t`` as a DMP with its goal in the scan's frame."""
    name = log.path.name
    frame = log.frame_at(frag.t0)
    if frame is None:
        raise LogError(f"{name}: no camera frame near t={frag.t0:.2f} s")
    room = room_histogram(frame.rgb, params.perception)
    scans_t = np.array([sc.t for sc in log.scans])
    i = int(np.searchsorted(scans_t, frag.t0 - 1e-6))
    if i >= len(scans_t) or scans_t[i] - frag.t0 > 0.2:
        raise LogError(f"{name}: no lidar scan within 0.2 s after t={frag.t0:.2f} s")
    msg = log.scans[i]
    scan = Scan2D.from_span(msg.ranges, msg.start_angle, msg.end_angle, LIDAR_RANGE_MAX)
    lidar_pose = wrap_yaw(compose(base[int(np.argmin(np.abs(base_t - msg.t)))], mount))
    goal = path[-1]
    salient = bool(np.hypot(goal[0] - lidar_pose[0], goal[1] - lidar_pose[1]) < params.scan_epsilon)
    if not salient:
        warnings.append(
            f"{name}: fragment {k + 1} ({frag.t0:.1f}-{frag.t1:.1f} s) ends farther than "
            f"{params.scan_epsilon} m from where its scan was taken; its goal is stored "
            "in odometry's frame"
        )
    action = action_in_scan_frame(t, path, lidar_pose if salient else None, params)
    perception = SalientPerceptions(
        cluster=None,
        weight=None,
        room=room,
        scan=scan if salient else None,
        scan_pose=lidar_pose if salient else None,
    )
    if poi is not None:  # a mobile manipulator's hand keeps what it holds while driving
        action = replace(action, poi=poi, gripper_start=grip, gripper_end=grip)
    return Smc(perception=perception, action=action)


BASE_MOVED = (0.05, 0.1)
"""A mobile manipulator's fragment drives the base when its base target moves this far
[m] or turns this much [rad]."""
HAND_MOVED = 0.02
"""... and moves the hand when the hand's target in the base's frame moves this far [m]."""


def mobile_manipulator_smcs(
    log: Log, frags: Sequence[Fragment], scene: Scene, params: SmcParams, warnings: list[str]
) -> list[Smc]:
    """The SMCs of a mobile manipulator's fragments (paper 5.3, docs/design.md 9), by what moved:

    - the base only (navigation): as a mobile base's, room colours and scan (SI, SL), the
      base path as the DMP (``poi="base"``); the hand rides along;
    - the hand (manipulation), the base standing: the object clusters of the RGB-D frame
      (ML) in odometry's frame, the hand's path in that frame as the DMP, its goal in the
      salient object's frame (``poi="hand"``);
    - both (pulling a door while backing up): as manipulation, plus the base's path as a
      second DMP of the same duration, its goal in the same object's frame.

    A manipulation that starts with the hand closed on something (pulling a handle,
    carrying the object) moves relative to the hand: its goal is in the frame of the hand's
    start pose and it has no salient object (the hand hides what it holds). Otherwise the
    salient object is the cluster nearest the hand where the action ends, within epsilon.
    """
    if not len(log.base_t):
        raise LogError(
            f"{log.path}: no /robot/base; a mobile manipulator's log needs its base pose"
        )
    mount = lidar_mount(scene.model(), None, _lidar_site(log, scene))
    robot = robot_model_of(log)
    hand_world = compose(
        log.base[np.clip(np.searchsorted(log.base_t, log.poi_t), 0, len(log.base_t) - 1)],
        log.poi,
    )
    cut: set[str] = set()
    smcs: list[Smc] = []
    held = 0.0
    for k, frag in enumerate(frags):
        m = _motion(log, frag)
        if m.drives and not m.reaches:
            nav = _navigation_smc(
                log,
                k,
                frag,
                m.t,
                m.base_path,
                log.base_t,
                log.base,
                mount,
                params,
                warnings,
                poi="base",
                grip=float(m.grip[-1]),
            )
            smcs.append(nav)
            continue
        holding = bool(m.grip[0] < 0.5)
        cluster = None
        if not holding:  # reaching for something: the object the hand ends at (ML)
            cluster = _reached_object(log, frag, robot, hand_world, params, warnings, cut)
        action = _hand_action(m, cluster, holding, held, params)
        if action.event == "close":
            held = cluster.yaw_period if cluster is not None else 0.0
        elif action.event == "open":
            held = 0.0
        if cluster is None and not holding:
            warnings.append(
                f"{log.path.name}: fragment {k + 1} ({frag.t0:.1f}-{frag.t1:.1f} s) ends with no "
                f"object within {params.epsilon} m of the hand; its goal is stored in the base's "
                "frame"
            )
        smcs.append(Smc(perception=SalientPerceptions(cluster=cluster, weight=None), action=action))
    return smcs


@dataclass(frozen=True, slots=True)
class _Motion:
    """What a mobile manipulator's fragment commanded, and what of the robot it moves."""

    t: np.ndarray
    """Command times from the fragment's start, shape (T,) [s]."""
    base: np.ndarray
    """Base targets ``[x, y, yaw]``, yaw unwrapped, shape (T, 3) [m, m, rad]."""
    hand: np.ndarray
    """Hand targets ``[x, y, z, yaw]`` in the base's frame, shape (T, 4) [m, rad]."""
    grip: np.ndarray
    """Gripper commands in [0, 1] (1 = open), shape (T,)."""
    drives: bool
    """The base target moves (:data:`BASE_MOVED`)."""
    reaches: bool
    """The hand target moves on the base (:data:`HAND_MOVED`)."""

    @property
    def base_path(self) -> np.ndarray:
        """The base targets as a POI path ``[x, y, 0, yaw]``, shape (T, 4)."""
        return np.column_stack([self.base[:, :2], np.zeros(len(self.base)), self.base[:, 2]])


def _motion(log: Log, frag: Fragment) -> _Motion:
    """The commands of ``frag``: base and hand targets, gripper, and what moves."""
    cmds = fragment_commands(log, frag)
    t = np.array([c.t for c in cmds]) - cmds[0].t
    if any(c.base is None for c in cmds):
        raise LogError(
            f"{log.path.name}: a command at t={frag.t0:.2f}-{frag.t1:.2f} s has no base target"
        )
    base = np.array([c.base for c in cmds], dtype=float)
    base[:, 2] = np.unwrap(base[:, 2])
    hand = np.array([c.target for c in cmds], dtype=float)
    drives = bool(
        np.linalg.norm(base[-1, :2] - base[0, :2]) > BASE_MOVED[0]
        or abs(base[-1, 2] - base[0, 2]) > BASE_MOVED[1]
    )
    reaches = bool(np.linalg.norm(hand[-1, :3] - hand[0, :3]) > HAND_MOVED)
    grip = np.array([c.gripper for c in cmds])
    return _Motion(t=t, base=base, hand=hand, grip=grip, drives=drives, reaches=reaches)


def _reached_object(
    log: Log,
    frag: Fragment,
    robot: RobotModel,
    hand_world: np.ndarray,
    params: SmcParams,
    warnings: list[str],
    cut: set[str],
) -> Cluster | None:
    """The salient object (ML) of a reach: of the clusters in the RGB-D frame at the
    fragment's start (in odometry's frame), the one nearest where the hand ends
    (``hand_world`` (N, 4) at the log's POI times), within epsilon; None if none is."""
    name = log.path.name
    frame = log.frame_at(frag.t0)
    if frame is None:
        raise LogError(f"{name}: no camera frame near t={frag.t0:.2f} s")
    base_then = log.base[int(np.argmin(np.abs(log.base_t - frame.t)))]
    geometry = geometry_at(robot, log, frame.t)
    clusters = clusters_from_frame(frame, geometry, params.perception, base_then)
    end = hand_world[int(np.argmin(np.abs(log.poi_t - frag.t1)))][:3]
    idx = salient_cluster(clusters, end, params.epsilon)
    cluster = None if idx is None else clusters[idx]
    if cluster is not None:  # shelves and doors run past a box that rides the base
        warnings += crop_warnings(name, frame.t, [cluster], params.perception, cut)
    return cluster


def _hand_action(
    m: _Motion, cluster: Cluster | None, holding: bool, held: float, params: SmcParams
) -> Action:
    """The action of a fragment that moves the hand (``poi="hand"``): its path in
    odometry's frame as the DMP, the goal in the frame of the hand's start pose when it
    ``holding`` something, else in ``cluster``'s, else in the base's; when the base
    ``drives`` too, its path as a second DMP, its goal in the same frame. ``held``: the
    symmetry of what the hand holds [rad]."""
    world = compose(m.base, m.hand)
    action = action_from_path(m.t, world, m.grip, cluster, params, held_symmetry=held)
    action = replace(action, poi="hand")
    if holding:
        # The hand holds what it moves (a handle, the object): where it goes follows from
        # where it holds it, whatever the hand hides of it. Goal, and the base's, in the
        # frame of the hand's start pose.
        action = replace(
            action,
            goal_frame="hand",
            goal=goal_in_hand(world[0], world[-1]),
            hand_yaw=float(world[0][3] - m.base[0][2]),
        )
    elif cluster is None:  # nothing to go by: the hand relative to the robot
        action = replace(action, goal_frame="base", goal=m.hand[-1].copy())
    if not m.drives:
        return action
    end = m.base_path[-1].copy()
    if holding:
        base_goal = goal_in_hand(world[0], end)
    else:
        base_goal = end if cluster is None else goal_in_object(end, cluster)
    return replace(action, base_dmp=dmp_mod.fit(m.t, m.base_path, params.dmp), base_goal=base_goal)
