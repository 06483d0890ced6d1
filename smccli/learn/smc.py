"""Sensory-Motor Contingencies (paper 3.7, eq. 40): salient perceptions + salient action.

An SMC is extracted from one fragment [t0, t1] of a demonstration:

- salient perceptions (3.3) are read at t0, the decision point: the scale's weight (SI,
  always salient) and the object cluster (ML) nearest the POI at t1, if within epsilon;
- a mobile base's perceptions (4.2) are the camera's whole-frame colour histogram (SI,
  always salient, eq. 17) and the lidar scan with the lidar's odometry pose (SL, salient
  when the fragment's goal lies within ``scan_epsilon`` of where it was taken, eq. 18);
- the salient action (3.4) is the commanded POI path over [t0, t1] as a DMP, its goal
  stored in the salient object's frame when there is one, else in the salient scan's
  frame (the lidar's pose at the scan, eq. 38-39), else in the world; the
  approach (the path's last centimetres, relative to the goal, in the same frame), the
  symmetry of that frame, and the gripper command at both ends (a discrete event, not a
  DMP dimension).

Object symmetry is a footprint period [rad] (``Cluster.yaw_period``): pi (elongated),
pi/2 (square), 0 (round: every rotation), 2 pi (none). The parallel gripper adds its own pi.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from smccli.learn import dmp as dmp_mod
from smccli.learn.dmp import Dmp
from smccli.learn.frames import goal_in_object, goal_in_scan, object_yaw
from smccli.learn.params import SmcParams
from smccli.perception import Cluster, cluster_from_dict, cluster_to_dict
from smccli.perception.scan import Scan2D, scan_from_dict, scan_to_dict
from smccli.world.geometry import TWO_PI, rotate_z, wrap

ROUND_STEPS = 72
"""Rotations tried for a round object (every 5 degrees) when aligning two goals."""


@dataclass(frozen=True, slots=True)
class SalientPerceptions:
    """The salient subset ^S P^{i,j} of a fragment's perceptions (eq. 16)."""

    cluster: Cluster | None
    """ML: the object cluster nearest the POI at the fragment's end (eq. 21-22), if any."""
    weight: float | None
    """SI: the scale reading at the decision point [kg]; None when the scene has no scale."""
    room: np.ndarray | None = None
    """SI: the camera's whole-frame colour histogram (:func:`~smccli.perception.room.
    room_histogram`), shape (histogram_size,); None for a robot without a base."""
    scan: Scan2D | None = None
    """SL value: the lidar scan at the decision point, when salient (eq. 18)."""
    scan_pose: np.ndarray | None = None
    """SL location: the lidar's pose ``[x, y, yaw]`` in odometry's frame when it took
    ``scan`` [m, m, rad]."""


@dataclass(frozen=True, slots=True)
class Action:
    """The salient action ^S A^{i,j}(omega, x_s, x_f, tau) (eq. 27)."""

    dmp: Dmp
    """Commanded POI path [x, y, z, yaw] over the fragment, as a DMP (eq. 28)."""
    goal_frame: str
    """``"object"``: ``goal`` is in the salient cluster's frame; ``"scan"``: in the frame of
    the lidar when it took the salient scan; ``"world"``: absolute."""
    goal: np.ndarray
    """POI goal x_f, shape (4,): [dx, dy, dz, dyaw] in the object's yawed frame or the
    lidar's frame [m, rad], or [x, y, z, yaw] in the world [m, rad]."""
    gripper_start: float
    """Gripper command at the fragment's start, in [0, 1] (1 = open)."""
    gripper_end: float
    """Gripper command at the fragment's end, in [0, 1]."""
    gripper_phase: float = 1.0
    """When the gripper command switched, as a fraction of the fragment's duration in
    (0, 1]; 1 = at the end. A grasp-and-lift fragment closes midway, then lifts."""
    symmetry: float = TWO_PI
    """Yaw symmetry of the goal's frame [rad]: the salient object's footprint period (pi,
    pi/2, 0 = round, 2 pi = none); 2 pi for a world goal. Goals that differ by such a
    rotation of the object are the same goal."""
    approach: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """How the POI came to the goal: the path's last ``approach_length`` metres, relative
    to the goal and in the goal's frame, sampled evenly along the path from the goal
    backwards, shape (n, 3) [m]; row 0 is the goal (zeros)."""
    held_symmetry: float = 0.0
    """Symmetry [rad] of the object held during the action (the one grasped by the chain's
    previous action), as ``symmetry``; 0 when nothing asymmetric is held. A held object
    without symmetry (2 pi) must not be turned by the gripper's pi."""
    poi: str | None = None
    """A mobile manipulator's: the POI ``dmp`` drives, ``"hand"`` (the end effector in the
    world, i.e. odometry's frame) or ``"base"`` (``[x, y, 0, yaw]``); None for a robot with
    one POI (docs/design.md 9)."""
    base_dmp: Dmp | None = None
    """A mobile manipulator's base path ``[x, y, 0, yaw]`` over the same fragment when hand
    and base both moved (pulling a door while backing up): two DMPs, one duration."""
    base_goal: np.ndarray | None = None
    """That path's goal ``[dx, dy, 0, dyaw]`` in ``goal``'s frame [m, rad], shape (4,)."""
    hand_yaw: float | None = None
    """With ``goal_frame == "hand"``: the hand's yaw relative to the base's when the action
    started [rad]. The frame's yaw is the hand's, which the gripper's half-turn symmetry
    leaves ambiguous by pi: replay takes the one nearest the base's yaw plus this."""

    @property
    def event(self) -> str:
        """The gripper event of the action: ``close``, ``open`` or ``none``."""
        if self.gripper_start >= 0.5 > self.gripper_end:
            return "close"
        if self.gripper_start < 0.5 <= self.gripper_end:
            return "open"
        return "none"


@dataclass(frozen=True, slots=True)
class Source:
    """Where an SMC came from: a fragment of a log."""

    log: str
    """File name of the log (informational)."""
    sha256: str
    """sha256 of the log file (hex)."""
    t0: float
    """Fragment start [s]."""
    t1: float
    """Fragment end [s]."""


@dataclass(frozen=True, slots=True)
class Smc:
    """S^{i,j} = (^S P^{i,j}, ^S A^{i,j}) (eq. 40)."""

    perception: SalientPerceptions
    action: Action


def symmetry_rotations(period: float) -> np.ndarray:
    """Rotations about z in [0, 2 pi) [rad] that map an object of footprint symmetry
    ``period`` onto itself (a round object: every 2 pi / ROUND_STEPS)."""
    step = TWO_PI / ROUND_STEPS if period <= 0 else period
    return np.arange(0.0, TWO_PI - 1e-9, step)


def common_symmetry(a: float, b: float) -> float:
    """The symmetry two estimates of one object share [rad]: the coarser one (round, 0,
    is the finest; none, 2 pi, the coarsest)."""
    return max(a, b)


def approach_in_frame(
    path: np.ndarray, frame_yaw: float, length: float, n_samples: int
) -> np.ndarray:
    """Where a POI path (T, >=3) came from on its way to its end (the goal): the points at
    which it last crossed the spheres of radius 0, length / (n - 1), ..., ``length`` [m]
    about the goal, relative to the goal and turned into a frame of yaw ``frame_yaw``
    [rad]; shape (n_samples, 3) [m]. A path that never gets that far stays at its farthest
    point.

    Spheres, not arc length: while the gripper closes, the operator's tremor jitters the
    target around the goal for a second or more, which adds centimetres of path length but
    never leaves a few millimetres' radius. Pauses and speed do not count either."""
    p = np.asarray(path, dtype=float)[:, :3]
    back = p[::-1] - p[-1]  # from the goal back in time
    dist = np.linalg.norm(back, axis=1)
    out = np.zeros((n_samples, 3))
    far = int(np.argmax(dist))
    for k, r in enumerate(np.linspace(0.0, length, n_samples)):
        if r <= 0.0:
            continue
        beyond = np.flatnonzero(dist >= r)
        if len(beyond) == 0:
            out[k] = back[far]
            continue
        i = int(beyond[0])  # the first sample back in time at distance >= r
        d0, d1 = dist[i - 1], dist[i]
        w = (r - d0) / (d1 - d0) if d1 > d0 else 1.0
        out[k] = back[i - 1] + w * (back[i] - back[i - 1])
    return rotate_z(out, -frame_yaw)


def action_from_path(
    t: np.ndarray,
    path: np.ndarray,
    gripper: np.ndarray,
    cluster: Cluster | None,
    params: SmcParams,
    *,
    held_symmetry: float = 0.0,
) -> Action:
    """Action saliency (3.4) of a fragment: the commanded POI ``path`` (T, 4) [m, rad] at
    times ``t`` (T,) [s] and gripper openings (T,) in [0, 1] -> the action, its goal and
    approach in ``cluster``'s frame (the salient object; the world when None)."""
    path = np.array(path, dtype=float)
    path[:, 3] = np.unwrap(path[:, 3])
    dmp = dmp_mod.fit(t, path, params.dmp)
    goal_world = path[-1].copy()
    goal_world[3] = wrap(goal_world[3])
    if cluster is not None:
        goal, frame = goal_in_object(goal_world, cluster), "object"
        symmetry, frame_yaw = cluster.yaw_period, object_yaw(cluster)
    else:
        goal, frame = goal_world, "world"
        symmetry, frame_yaw = TWO_PI, 0.0
    grip = np.asarray(gripper, dtype=float)
    switches = np.nonzero(np.abs(np.diff(grip)) > 0.25)[0]
    # The last switch of the gripper command, as a phase of the fragment (1 = at its end).
    phase = float(t[switches[-1] + 1] / t[-1]) if len(switches) and t[-1] > 0 else 1.0
    return Action(
        dmp=dmp,
        goal_frame=frame,
        goal=goal,
        gripper_start=float(grip[0]),
        gripper_end=float(grip[-1]),
        gripper_phase=min(max(phase, 1e-3), 1.0),
        symmetry=symmetry,
        approach=approach_in_frame(
            path, frame_yaw, params.approach_length, params.approach_samples
        ),
        held_symmetry=held_symmetry,
    )


def action_in_scan_frame(
    t: np.ndarray, path: np.ndarray, lidar_pose: np.ndarray | None, params: SmcParams
) -> Action:
    """Action saliency (3.4) of a mobile base's fragment: the commanded base path ``path``
    (T, 4) ``[x, y, 0, yaw]`` [m, rad] at times ``t`` (T,) [s] as a DMP, its goal relative to
    the lidar's pose ``lidar_pose`` ``[x, y, yaw]`` at the salient scan (G_rel = L^-1 G,
    eq. 38-39), or in the world when no scan is salient (None).

    No approach is stored: the last centimetres of a base's path point back to where it
    started, which follows from the layout, not from the action (a holonomic base's
    heading is in the goal)."""
    path = np.array(path, dtype=float)
    path[:, 3] = np.unwrap(path[:, 3])
    dmp = dmp_mod.fit(t, path, params.dmp)
    gx, gy, _, gyaw = path[-1]
    if lidar_pose is None:
        goal, frame = np.array([gx, gy, 0.0, wrap(gyaw)]), "world"
    else:
        dx, dy, dyaw = goal_in_scan(np.array([gx, gy, gyaw]), np.asarray(lidar_pose))
        goal, frame = np.array([dx, dy, 0.0, dyaw]), "scan"
    return Action(
        dmp=dmp,
        goal_frame=frame,
        goal=goal,
        gripper_start=1.0,
        gripper_end=1.0,
        symmetry=TWO_PI,
        approach=np.zeros((0, 3)),
        held_symmetry=TWO_PI,
    )


# --- JSON (no pickle: every value is a list of floats, a number or a string) -------------


def _to_json(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, tuple):
        return [_to_json(v) for v in value]
    return value


def smc_to_dict(smc: Smc) -> tuple[dict[str, Any], dict[str, Any]]:
    """(perception, action) JSON objects of an SMC, as stored on a tree edge."""
    p = smc.perception
    a = smc.action
    perception: dict[str, Any] = {
        "cluster": None if p.cluster is None else cluster_to_dict(p.cluster),
        "weight": p.weight,
    }
    if p.room is not None:  # a mobile base's; arm trees keep their two keys
        perception["room"] = _to_json(p.room)
        perception["scan"] = None if p.scan is None else scan_to_dict(p.scan)
        perception["scan_pose"] = None if p.scan_pose is None else _to_json(p.scan_pose)
    action: dict[str, Any] = {
        "event": a.event,
        "goal_frame": a.goal_frame,
        "goal": _to_json(a.goal),
        "gripper_start": a.gripper_start,
        "gripper_end": a.gripper_end,
        "gripper_phase": a.gripper_phase,
        "symmetry": a.symmetry,
        "held_symmetry": a.held_symmetry,
        "approach": _to_json(a.approach),
        "dmp": dmp_mod.to_dict(a.dmp),
    }
    if a.poi is not None:  # a mobile manipulator's; other trees keep their keys
        action["poi"] = a.poi
    if a.base_dmp is not None and a.base_goal is not None:
        action["base_dmp"] = dmp_mod.to_dict(a.base_dmp)
        action["base_goal"] = _to_json(a.base_goal)
    if a.hand_yaw is not None:
        action["hand_yaw"] = a.hand_yaw
    return perception, action


def smc_from_dict(perception: dict[str, Any], action: dict[str, Any]) -> Smc:
    """Inverse of :func:`smc_to_dict`."""
    cluster = perception.get("cluster")
    room, scan, scan_pose = (perception.get(k) for k in ("room", "scan", "scan_pose"))
    return Smc(
        perception=SalientPerceptions(
            cluster=None if cluster is None else cluster_from_dict(cluster),
            weight=perception.get("weight"),
            room=None if room is None else np.asarray(room, dtype=float),
            scan=None if scan is None else scan_from_dict(scan),
            scan_pose=None if scan_pose is None else np.asarray(scan_pose, dtype=float),
        ),
        action=Action(
            dmp=dmp_mod.from_dict(action["dmp"]),
            goal_frame=str(action["goal_frame"]),
            goal=np.asarray(action["goal"], dtype=float),
            gripper_start=float(action["gripper_start"]),
            gripper_end=float(action["gripper_end"]),
            gripper_phase=float(action.get("gripper_phase", 1.0)),
            symmetry=float(action["symmetry"]),
            held_symmetry=float(action["held_symmetry"]),
            approach=np.asarray(action["approach"], dtype=float).reshape(-1, 3),
            poi=None if action.get("poi") is None else str(action["poi"]),
            base_dmp=None if "base_dmp" not in action else dmp_mod.from_dict(action["base_dmp"]),
            base_goal=(
                None if "base_goal" not in action else np.asarray(action["base_goal"], float)
            ),
            hand_yaw=None if action.get("hand_yaw") is None else float(action["hand_yaw"]),
        ),
    )
