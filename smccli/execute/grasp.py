"""Room for the fingers: a grasp placed where its fingers can go down.

A demonstrated grasp comes back in the object's frame (eq. 38-39): the fingers go down on
either side of the object as they did in the demonstration, opened as wide as the operator
opened them. Beside a neighbour, a finger may come down on it instead: measured on the
look-alike family (docs/figures.md), every touching grasp that missed had a look-alike
where a finger had to go. A person then grasps the object a little further along, or opens
the hand less. So does this module, from what the robot sees and its own model only:

- :func:`finger_columns` -- the fingers as boxes in the POI's frame at each opening, from
  the robot's MJCF (their collision geoms with the finger joints at that opening);
- :func:`solid_neighbours` -- what stands beside the object, each box among it whole
  (a depth camera loses an object's corners);
- :func:`clear_grasp` -- where the demonstrated grasp's finger columns hold points of
  something else (the decision's cloud, less the grasped object), the nearest grasp along
  the object (the POI's x) and the widest opening whose columns are empty; the
  demonstrated one wherever it is empty, or where nothing is.

The POI's frame: x its yaw axis (along which a finger is wide), y the closing axis, z the
approach (down at a grasp); see docs/robots.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import mujoco
import numpy as np

from smccli.perception import Cluster
from smccli.perception.dbscan import dbscan_labels
from smccli.perception.params import PerceptionParams
from smccli.world.geometry import compose, from_frame, to_frame
from smccli.world.robot import Robot
from smccli.world.robot_model import subtree_bodies

OPENINGS = np.linspace(1.0, 0.3, 15)
"""Openings [0-1] tried, widest first (the demonstrated one is tried before them)."""
STEP = 0.005
"""Spacing of the grasps tried along the object [m]."""
MAX_SHIFT = 0.05
"""Farthest a grasp moves along the object from the demonstrated one [m]."""
MARGIN = 0.005
"""Room kept around a finger's column [m]: depth noise and the hand's tracking error."""
GRIP_MARGIN = 0.008
"""Least room between an open finger and the grasped object's side [m]."""
ON_OBJECT = 0.01
"""A moved grasp keeps its fingers this far inside the object's ends [m]."""
TIGHT_MARGIN = 0.003
"""Room kept around a finger's column where no grasp has :data:`MARGIN` [m]: a neighbour
1.6 cm from the object leaves a finger 2-3 mm either side, and the demonstrated grasp
would put the finger on the neighbour (development seed 1's trial 136)."""
TIGHT_GRIP_MARGIN = 0.006
"""Least room between an open finger and the object's side with :data:`TIGHT_MARGIN` [m]."""
LAST_MARGIN = 0.0015
"""Room kept around a finger's column where no grasp has :data:`TIGHT_MARGIN` [m]: the
hand tracks its path within 1 mm, and a neighbour 1.5-1.6 cm from the object leaves the
finger (1.2 cm thick) 1-2 mm either side (development seed 6's 32, seed 8's 100); the
demonstrated grasp would put the finger on it."""
LAST_GRIP_MARGIN = 0.003
"""Least room between an open finger and the object's side with :data:`LAST_MARGIN` [m]."""
MIN_POINTS = 3
"""Points in a column that make it occupied (fewer: noise)."""
FILL_STEP = 0.004
"""Spacing of the points a neighbour's footprint is filled with [m]: a finger's column
(2.4 x 1.2 cm at the pads) then holds dozens, against :data:`MIN_POINTS`."""
TOP_QUANTILE = 0.95
"""A filled neighbour stands as high as this quantile of its points (the highest one may
be a flying pixel)."""
ABOVE_TIP = 0.003
"""Points lower than this above the fingertips' height at the grasp do not block it [m]
(what is left of the table)."""


@dataclass(frozen=True)
class FingerColumns:
    """A parallel gripper's fingers in the POI's frame, at each of ``openings``."""

    openings: np.ndarray
    """(k,) openings [0-1], descending."""
    inner: np.ndarray
    """(k,) nearest any finger comes to the POI along the closing axis (y) [m]: half the
    room between the pads."""
    outer: np.ndarray
    """(k,) farthest any finger reaches along y [m]."""
    half_width: float
    """Half the fingers' extent along x [m]."""
    tip: float
    """How far the fingertips reach past the POI along the approach (z) [m]."""

    def inner_at(self, opening: float) -> float:
        """:attr:`inner` at ``opening`` (linear between the samples) [m]."""
        return float(np.interp(opening, self.openings[::-1], self.inner[::-1]))

    def outer_at(self, opening: float) -> float:
        """:attr:`outer` at ``opening`` [m]."""
        return float(np.interp(opening, self.openings[::-1], self.outer[::-1]))


def finger_columns(model: mujoco.MjModel, robot: Robot) -> FingerColumns | None:
    """The fingers of ``robot`` in ``model`` (a scene holding it) as boxes in the POI's
    frame: the corners of their colliding geoms' bounding boxes with every finger joint at
    each opening of :data:`OPENINGS`. None without a gripper."""
    g = robot.gripper
    if g is None:
        return None
    joints = [model.joint(n).id for n in g.joints]
    bodies = subtree_bodies(model, {int(model.jnt_bodyid[j]) for j in joints})
    geoms = [
        i
        for i in range(model.ngeom)
        if int(model.geom_bodyid[i]) in bodies
        and (model.geom_contype[i] or model.geom_conaffinity[i])
    ]
    if not geoms:
        return None
    site = model.site(robot.poi).id
    data = mujoco.MjData(model)
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    inner, outer, half_width, tip = [], [], 0.0, -math.inf
    for opening in OPENINGS:
        for j in joints:
            data.qpos[model.jnt_qposadr[j]] = g.closed + opening * (g.open - g.closed)
        mujoco.mj_kinematics(model, data)
        R_site = data.site_xmat[site].reshape(3, 3)
        corners = []
        for i in geoms:
            centre, half = model.geom_aabb[i, :3], model.geom_aabb[i, 3:]
            local = centre + signs * half
            world = data.geom_xpos[i] + local @ data.geom_xmat[i].reshape(3, 3).T
            corners.append((world - data.site_xpos[site]) @ R_site)
        c = np.concatenate(corners)
        inner.append(float(np.min(np.abs(c[:, 1]))) if np.ptp(np.sign(c[:, 1])) else 0.0)
        outer.append(float(np.max(np.abs(c[:, 1]))))
        half_width = max(half_width, float(np.max(np.abs(c[:, 0]))))
        tip = max(tip, float(np.max(c[:, 2])))
    return FingerColumns(OPENINGS.copy(), np.array(inner), np.array(outer), half_width, tip)


def _frame(cluster: Cluster) -> np.ndarray:
    """The cluster's footprint frame ``[x, y, yaw]``: its centre, x along its length."""
    return np.array([cluster.centroid[0], cluster.centroid[1], cluster.yaw])


def others(points: np.ndarray, target: Cluster, grow: float = MARGIN) -> np.ndarray:
    """``points`` (n, 3) [m] outside the target's footprint grown by ``grow`` [m]: what
    stands beside the object grasped."""
    local = to_frame(_frame(target), points[:, :2])
    inside = np.all(np.abs(local) <= target.extents[:2] / 2 + grow, axis=1)
    return points[~inside]


def solid_neighbours(points: np.ndarray, params: PerceptionParams) -> np.ndarray:
    """``points`` (n, 3) [m] of what stands beside the grasped object (:func:`others`), with
    the footprint of each neighbour that is a box filled in at its top's height: (m, 3),
    the n first.

    A depth camera loses the pixels along an object's edges, and at a corner along two:
    measured on the look-alike family (development seed 4, four misses in 200 trials), the
    near corners of a look-alike 1-2 cm from the white box had no point within 1 cm, and a
    finger came down on one of them. A neighbour (a DBSCAN cluster of ``points``) whose
    seen footprint fills its smallest rectangle as a box's does (``round_fill``, the test
    that tells a box from a cylinder in :mod:`~smccli.perception.clusters`) fills that
    rectangle; a round one stays as seen."""
    labels = dbscan_labels(points, params.dbscan_eps, params.dbscan_min_points)
    solid = [points]
    for k in range(int(labels.max(initial=-1)) + 1):
        mine = points[labels == k]
        xy = mine[:, :2].astype(np.float32)
        rect = cv2.minAreaRect(xy)
        area = float(rect[1][0] * rect[1][1])
        if area <= 0 or cv2.contourArea(cv2.convexHull(xy)) < params.round_fill * area:
            continue
        c0, c1, _, c3 = cv2.boxPoints(rect).astype(np.float64)
        s = np.linspace(0.0, 1.0, int(np.ceil(np.hypot(*(c1 - c0)) / FILL_STEP)) + 1)
        t = np.linspace(0.0, 1.0, int(np.ceil(np.hypot(*(c3 - c0)) / FILL_STEP)) + 1)
        grid = c0 + s[:, None, None] * (c1 - c0) + t[None, :, None] * (c3 - c0)
        top = float(np.quantile(mine[:, 2], TOP_QUANTILE))
        solid.append(np.c_[grid.reshape(-1, 2), np.full(grid.shape[0] * grid.shape[1], top)])
    return np.vstack(solid)


def clear_grasp(
    goal: np.ndarray,
    opening: float,
    target: Cluster,
    points: np.ndarray,
    fingers: FingerColumns,
) -> tuple[np.ndarray, float, float]:
    """The grasp ``goal`` ``[x, y, z, yaw]`` (gripper down) with the fingers ``opening``
    [0-1] on ``target``, moved where the finger columns are empty of ``points`` (n, 3)
    [m], what stands beside it (:func:`others`), and so is the space between them, which
    the fingers sweep as they close. Returns (goal, opening, shift along the POI's x [m]):
    the demonstrated ones where that is empty or where no grasp tried is (the nearest
    shift first, and at each the widest opening); a grasp with :data:`MARGIN` around its
    fingers before one with only :data:`TIGHT_MARGIN`, and that before one with
    :data:`LAST_MARGIN`."""
    high = points[points[:, 2] > goal[2] - fingers.tip + ABOVE_TIP]
    px, py = to_frame(goal[[0, 1, 3]], high[:, :2]).T  # the POI's x and y at the grasp
    py = np.abs(py)
    half = target.extents[:2] / 2
    corners = from_frame(_frame(target), half * [[1, 1], [-1, 1], [-1, -1], [1, -1]])
    box = to_frame(goal[[0, 1, 3]], corners)
    side = float(np.max(np.abs(box[:, 1])))  # the object's farthest side along y
    length = float(np.ptp(box[:, 0]))
    reach = min(MAX_SHIFT, max(0.0, length / 2 - fingers.half_width - ON_OBJECT))
    steps = math.floor(reach / STEP + 1e-9)

    def empty(shift: float, o: float, margin: float) -> bool:
        # The columns and what lies between them: the fingers close across it, and a
        # neighbour between a finger and the object is squeezed in with it (development
        # seeds 8 and 9: both boxes lifted together, or the grip blocked open on them).
        near = np.abs(px - shift) < fingers.half_width + margin
        return int(np.count_nonzero(near & (py < fingers.outer_at(o) + margin))) < MIN_POINTS

    if empty(0.0, opening, MARGIN):
        return goal, opening, 0.0
    openings = [opening] + [o for o in OPENINGS if o < opening]
    shifts = sorted((STEP * k for k in range(-steps, steps + 1)), key=lambda v: (abs(v), v))
    passes = ((MARGIN, GRIP_MARGIN), (TIGHT_MARGIN, TIGHT_GRIP_MARGIN))
    for margin, grip_margin in (*passes, (LAST_MARGIN, LAST_GRIP_MARGIN)):
        for shift in shifts:
            for o in openings:
                if fingers.inner_at(o) < side + grip_margin:
                    break
                if empty(shift, o, margin):
                    return shifted(goal, shift), float(o), shift
    return goal, opening, 0.0


def shifted(goal: np.ndarray, shift: float) -> np.ndarray:
    """``goal`` ``[x, y, z, yaw]`` moved ``shift`` [m] along its own x (a new array)."""
    return compose(goal, [shift, 0.0, 0.0, 0.0])
