"""Goal frames: where an action's goal is stored, and how it comes back (eq. 38-39, 46).

A demonstrated goal is stored relative to what the robot can find again (compile), then
mapped back into the world at a decision (replay) or for display (inspect):

* ``object`` -- the salient object's frame: its centroid, turned by its footprint's yaw
  (none for a round one); the object's and the gripper's symmetries leave several yaws,
  the one nearest the wrist's is taken (:func:`goal_from_object`);
* ``scan`` -- the lidar's pose when the salient scan was taken (a base's goal): the scan
  aligned today tells where that pose is now, odometry's drift cancels (eq. 38-39);
* ``hand`` -- the hand's pose at the fragment's start, when it holds what it moves (a
  handle): the goal follows from where it holds it;
* ``base`` -- a mobile manipulator's hand relative to its base: a posture;
* ``world`` -- nothing to go by: the goal as taught.

Goals are ``[x, y, z, yaw]`` [m, m, m, rad] (a base's ``z`` is 0); the pose math is
:mod:`smccli.world.geometry`'s. Storing and mapping back sit side by side so each pair
stays inverse (tests/test_frames.py checks the round trips).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol

import numpy as np

from smccli.errors import SmcError
from smccli.perception import Cluster
from smccli.perception.scan import ScanAlignment
from smccli.world.geometry import (
    TWO_PI,
    between,
    compose,
    from_frame,
    near,
    se2,
    se2_pose,
    wrap,
    wrap_yaw,
)


class Action(Protocol):
    """What mapping a goal back reads of an action: the fields of
    :class:`smccli.learn.smc.Action` of the same names (that module stores goals with this
    one's functions, so this one names the fields instead of importing the class)."""

    @property
    def goal_frame(self) -> str:
        """``world``, ``object``, ``scan``, ``hand`` or ``base``."""

    @property
    def goal(self) -> np.ndarray:
        """The goal in ``goal_frame``, shape (4,) [m, rad]."""

    @property
    def poi(self) -> str | None:
        """``hand``, ``base`` or None (a robot with one POI)."""

    @property
    def symmetry(self) -> float:
        """Yaw symmetry of the goal's frame [rad]."""

    @property
    def held_symmetry(self) -> float:
        """Yaw symmetry of the object held [rad]."""

    @property
    def base_goal(self) -> np.ndarray | None:
        """A mobile manipulator's base goal in ``goal_frame``, shape (4,)."""

    @property
    def hand_yaw(self) -> float | None:
        """With ``goal_frame == "hand"``: the hand's yaw on its base as taught [rad]."""


# --- object ----------------------------------------------------------------------------


def object_yaw(cluster: Cluster) -> float:
    """Yaw that defines the object's frame: 0 for round footprints, where yaw is undefined."""
    return 0.0 if cluster.yaw_period <= 0 else float(cluster.yaw)


def goal_in_object(goal_world: np.ndarray, cluster: Cluster) -> np.ndarray:
    """World POI goal ``[x, y, z, yaw]`` -> ``[dx, dy, dz, dyaw]`` in the cluster's yawed
    frame, dyaw in (-pi, pi]."""
    frame = np.array([*cluster.centroid, object_yaw(cluster)])
    return wrap_yaw(between(frame, goal_world))


def goal_from_object(
    goal_obj: np.ndarray,
    cluster: Cluster,
    near_yaw: float,
    *,
    flip: bool = True,
    taught_yaw: float | None = None,
    yaw_ok: Callable[[np.ndarray], bool] | None = None,
) -> np.ndarray:
    """Contingent action mapping of the goal (eq. 38-39): object-frame goal -> world.

    The footprint's symmetry (``yaw_period``) and the parallel gripper's (pi) leave several
    equivalent goal yaws; the one nearest ``near_yaw`` (the current POI yaw) is taken, so
    the wrist turns as little as possible. The offset turns with the chosen object yaw.
    ``flip=False`` forbids the gripper's pi: an object without symmetry that is grasped or
    held keeps its orientation in the hand, so it is not placed turned by pi.

    The gripper's pi and an object's half-turn symmetry give the same goal yaw from two
    object yaws a half turn apart, which put the offset on opposite sides of the centre.
    ``taught_yaw`` (the demonstrated cluster's yaw [rad]) settles that tie: the object yaw
    nearest it keeps the offset on the side it was taught, e.g. towards the camera when the
    cluster's centre sits behind a bar handle (its posts pull it back).

    ``yaw_ok`` (a goal ``[x, y, z, yaw]`` -> bool) leaves out goals the wrist reaches only
    the long way round, past its limit (``CartesianController.wrist_short_way``), which
    would turn the hand a full turn with the object in it. If none is left, as without it.
    """
    base = object_yaw(cluster)
    period = cluster.yaw_period if cluster.yaw_period > 0 else math.pi

    def goal_at(obj_yaw: float, yaw: float) -> np.ndarray:
        return np.array([*from_frame([*cluster.centroid, obj_yaw], goal_obj[:3]), yaw])

    def pick(ok: Callable[[np.ndarray], bool] | None) -> np.ndarray | None:
        best: tuple[float, float, float, float] | None = None
        for k_obj in range(-4, 5):
            obj_yaw = base + k_obj * period
            if cluster.yaw_period <= 0 and k_obj != 0:
                continue
            turn = 0.0 if taught_yaw is None else abs(wrap(obj_yaw - taught_yaw))
            for k_grip in range(-2, 3) if flip else range(-1, 2):
                yaw = obj_yaw + goal_obj[3] + k_grip * (math.pi if flip else TWO_PI)
                dist = abs(yaw - near_yaw)
                if (
                    best is None
                    or dist < best[0] - 1e-9
                    or (dist < best[0] + 1e-9 and turn < best[3] - 1e-9)
                ) and (ok is None or ok(goal_at(obj_yaw, yaw))):
                    best = (dist, yaw, obj_yaw, turn)
        return None if best is None else goal_at(best[2], best[1])

    goal = pick(yaw_ok) if yaw_ok is not None else None
    if goal is None:
        goal = pick(None)
    assert goal is not None
    return goal


# --- scan ------------------------------------------------------------------------------


def goal_in_scan(goal_world: np.ndarray, lidar_world: np.ndarray) -> np.ndarray:
    """G_rel = L_demo^-1 * G_demo: a demonstrated base goal ``[x, y, yaw]`` in the frame
    of the lidar at the demo scan, both in odometry's frame; yaw in (-pi, pi].

    Stored with the scan, it no longer depends on where odometry's world frame was during
    the demo."""
    return wrap_yaw(between(lidar_world, goal_world))


def goal_at_scan_pose(goal_rel: np.ndarray, lidar_world: np.ndarray) -> np.ndarray:
    """Inverse of :func:`goal_in_scan`: a goal stored with a scan ``[x, y, yaw]`` back in
    the frame the scan's pose is in (the demo's odometry), yaw in (-pi, pi]."""
    return wrap_yaw(compose(lidar_world, goal_rel))


def goal_from_scan(
    goal_rel: np.ndarray, T_demo_now: np.ndarray | ScanAlignment, lidar_now: np.ndarray
) -> np.ndarray:
    """The goal x_f* of eq. 38-39 for a goal stored with a scan: G_now = L_now * T^-1 * G_rel.

    ``goal_rel`` from :func:`goal_in_scan`; ``T_demo_now`` the current lidar in the demo
    lidar's frame (:func:`~smccli.perception.scan.align_scans`, target = the demo scan,
    source = the current one); ``lidar_now`` the current lidar pose in odometry's frame.
    Returns the base goal ``[x, y, yaw]`` in today's odometry frame: the demonstrated
    place in the room, whatever odometry's drift since the demo."""
    T = T_demo_now.T_target_source if isinstance(T_demo_now, ScanAlignment) else T_demo_now
    return se2_pose(se2(lidar_now) @ np.linalg.inv(np.asarray(T)) @ se2(goal_rel))


# --- hand ------------------------------------------------------------------------------


def goal_in_hand(hand_start: np.ndarray, goal_world: np.ndarray) -> np.ndarray:
    """A goal ``[x, y, z, yaw]`` in the yawed frame of the hand's start pose (yaw
    unwrapped: the wrist turns as it did)."""
    return between(hand_start, goal_world)


def hand_frame(hand: np.ndarray, base: np.ndarray | None, hand_yaw: float | None) -> np.ndarray:
    """The frame of a goal relative to the hand ``[x, y, z, yaw]``: the hand's pose, its
    yaw (ambiguous by the gripper's pi) taken nearest the base's ``[x, y, yaw]`` plus
    ``hand_yaw``, the hand's yaw on its base as taught."""
    frame = np.array(hand, dtype=float)
    if hand_yaw is not None and base is not None:
        frame[3] = near(float(hand[3]), float(base[2]) + hand_yaw, math.pi)
    return frame


# --- every frame -----------------------------------------------------------------------


def map_goal(
    action: Action,
    cluster: Cluster | None,
    start: np.ndarray,
    *,
    gripper: bool,
    alignment: ScanAlignment | np.ndarray | None = None,
    lidar_pose: np.ndarray | None = None,
    base: np.ndarray | None = None,
    taught: Cluster | None = None,
    edge: str | None = None,
    yaw_ok: Callable[[np.ndarray], bool] | None = None,
) -> np.ndarray:
    """Contingent action mapping of the goal (eq. 38-39, 46): the action's goal in the
    world ``[x, y, z, yaw]``, the yaw the turn nearest the POI's now.

    ``start`` the POI now; ``cluster`` the context cluster the SMC matched (``taught``:
    the demonstrated one); ``gripper`` whether the robot has one; a scan-frame goal needs
    the ``alignment`` of the taught scan to today's and the ``lidar_pose`` now; a goal in a
    mobile manipulator's base frame needs the ``base`` pose ``[x, y, yaw]``. ``edge`` names
    the SMC in errors; ``yaw_ok``: of an object-frame goal's equivalent yaws, those the
    wrist reaches the short way (:func:`goal_from_object`)."""
    if action.goal_frame == "scan":
        if alignment is None or lidar_pose is None:
            raise SmcError(
                f"edge {edge}: a goal in the taught scan's frame needs that scan aligned at "
                "this decision and the lidar's pose"
            )
        x, y, yaw = goal_from_scan(action.goal[[0, 1, 3]], alignment, lidar_pose)
        return np.array([x, y, 0.0, near(yaw, start[3])])
    if action.goal_frame == "hand":  # relative to the hand's pose now (it holds a handle)
        goal = compose(hand_frame(start, base, action.hand_yaw), action.goal)
        goal[3] = start[3] + float(action.goal[3])  # the wrist turns as it did
        return goal
    if not gripper or action.poi == "base":  # a base's world goal
        goal = np.array(action.goal, dtype=float)
        goal[3] = near(float(goal[3]), start[3])
        return goal
    # A parallel gripper is symmetric under a half turn, so the wrist may take the short
    # way round, unless the object grasped or held has no symmetry: then the half turn
    # would put its other side where the demonstration put this one.
    asymmetric = max(action.held_symmetry, action.symmetry if cluster else 0.0)
    flip = asymmetric < TWO_PI - 1e-6
    if action.goal_frame == "object" and cluster is not None:
        flip = flip and cluster.yaw_period < TWO_PI - 1e-6
        taught_yaw = None if taught is None else float(taught.yaw)
        goal = goal_from_object(
            action.goal,
            cluster,
            near_yaw=float(start[3]),
            flip=flip,
            taught_yaw=taught_yaw,
            yaw_ok=yaw_ok,
        )
    else:
        goal = np.array(action.goal, dtype=float)
        if action.goal_frame == "base":  # a mobile manipulator's hand, relative to it
            if base is None:
                raise SmcError(f"edge {edge}: a goal in the base's frame needs its pose")
            goal = compose(base, goal)
            # A pose of the hand relative to the base is a posture: the wrist ends as
            # taught, not by the gripper's half turn, which swings the elbow elsewhere (and
            # the arm may then hide what the head camera must see).
            flip = False
        if flip:
            goal[3] = near(float(goal[3]), start[3], math.pi)
    goal[3] = near(float(goal[3]), start[3])
    return goal


def map_base_goal(
    action: Action, cluster: Cluster | None, base_now: np.ndarray, hand_now: np.ndarray
) -> np.ndarray:
    """Where a mobile manipulator's base goes while its hand acts (``action.base_goal``),
    ``[x, y, 0, yaw]`` from its pose now ``base_now`` ``[x, y, 0, yaw]`` and the hand's:
    in the salient object's frame, the object's yaw taken nearest the base's heading (a
    base does not turn round with an elongated handle's symmetry); else as taught."""
    assert action.base_goal is not None
    if action.goal_frame == "hand":
        frame = hand_frame(hand_now, base_now[[0, 1, 3]], action.hand_yaw)
        g = compose(frame, action.base_goal)
        g[2] = 0.0
    elif action.goal_frame == "object" and cluster is not None:
        g = goal_from_object(action.base_goal, cluster, near_yaw=float(base_now[3]), flip=False)
        g[2] = 0.0
    else:
        g = np.array(action.base_goal, dtype=float)
    g[3] = near(float(g[3]), float(base_now[3]))
    return g
