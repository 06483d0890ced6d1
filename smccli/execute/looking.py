"""Looking again while an arm acts on an object: where the object went, and the
rest of the path bent onto its new goal.

The executor looks every :data:`LOOK_PERIOD` through a crop box around the object
(:func:`look_crop`); :func:`find_again` says which cluster of that frame is the object and
whether its goal should move; :func:`steer` bends the path already streamed onto the DMP
rolled out to the new goal. Which SMC runs is not reconsidered: decisions stay as the
paper has them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from smccli.errors import SmcError
from smccli.execute.sensing import Sensors
from smccli.learn.dmp import min_jerk
from smccli.learn.params import SmcParams
from smccli.perception import Cluster, PerceptionParams, clusters_from_frame, d_cluster
from smccli.perception.cloud import view_region
from smccli.perception.distance import d_extents
from smccli.world.sensors import CameraFrame, RobotGeometry

LOOK_PERIOD = 1.0
"""While an arm acts on an object, it looks at it again this often [s]; 0 = off. A look
that finds the object's pixels as they were perceives nothing
(:mod:`~smccli.execute.tracking`: about 1 ms with an ideal camera); else it costs the
window of a camera frame that sees the table around the object and its clusters
(:func:`look`: about 12 ms at 320x240 on a 2-core machine). A push is caught if a look
comes before the hand is within :data:`LOOK_NEAR` of the object."""
LOOK_MARGIN = 0.05
"""A look's crop box reaches this far beyond where the object may have gone [m]: table
around it for the plane fit and the brightness ring."""
LOOK_NEAR = 0.06
"""It stops looking once the hand is this close to where it acts [m]: the fingers hide the
object and the view would pull the goal onto what is left of it."""
LOOK_RADIUS = 0.08
"""Looking again, the object acted on is sought this far from where it was last seen [m]:
a push of a few centimetres, not another object across the table."""
LOOK_MOVED = 0.01
"""It has moved when its centre is this far from where it was last seen [m]; less is the
noise of one view against another (a box's centre wanders 2-5 mm from frame to frame
under the realistic sensors)."""
LOOK_MOVED_HIDDEN = 0.03
"""A partly hidden view (:attr:`Cluster.hidden`) has moved only this far [m]: its centre
is off by what the arm hides of it, 1-2 cm on a box."""
LOOK_SAME_SIZE = 0.1
"""A partly hidden view counts only with its extents within this log-ratio (10 %) of the
last view's: an arm over a third of a box moves its centre by centimetres."""
LOOK_BETTER = 0.02
"""A view that has not moved replaces the last one when its D_P to the taught perception is
this much lower: seen whole where it was partly hidden, not the noise of two views of one
pose (D_P 0.002-0.01 apart)."""


def check_look_period(look_period: float) -> None:
    """SmcError (one line, exit 2) unless ``look_period`` is a number >= 0 [s]."""
    if not (math.isfinite(look_period) and look_period >= 0):
        raise SmcError(
            f"--look-period must be a number of seconds >= 0 (0: never look again), "
            f"got {look_period:g}"
        )


def look_crop(seen: Cluster, params: PerceptionParams) -> PerceptionParams:
    """The perception settings of a look at ``seen``: the crop box narrowed to the table
    around it, :data:`LOOK_RADIUS` plus :data:`LOOK_MARGIN` beyond its footprint and
    :data:`LOOK_MARGIN` above its top (what stands higher is the hand over it, or out of
    reach of a push): a small part of the image, the table still dominating it for the
    plane fit."""
    half = float(np.max(seen.extents[:2])) / 2 + LOOK_RADIUS + LOOK_MARGIN
    lo, hi = np.asarray(params.crop_min, float), np.asarray(params.crop_max, float)
    lo[:2] = np.maximum(lo[:2], seen.centroid[:2] - half)
    hi[:2] = np.minimum(hi[:2], seen.centroid[:2] + half)
    top = float(seen.centroid[2] + seen.extents[2] / 2) + LOOK_MARGIN
    hi[2] = max(min(hi[2], top), lo[2])
    return replace(params, crop_min=tuple(lo.tolist()), crop_max=tuple(hi.tolist()))


def look_frame(sensors: Sensors, seen: Cluster, params: PerceptionParams) -> CameraFrame:
    """A look's frame: the part of the image that can see into :func:`look_crop`'s box
    (:func:`~smccli.perception.cloud.view_region`), the rest left unread."""
    K, T, shape, near = sensors.camera_view()
    return sensors.render_camera(view_region(K, T, shape, near, look_crop(seen, params)))


def look(
    sensors: Sensors, seen: Cluster, params: PerceptionParams, frame: CameraFrame | None = None
) -> tuple[Cluster, ...]:
    """The clusters of a look at ``seen``: its frame (:func:`look_frame`, unless given)
    perceived through :func:`look_crop`'s box (:func:`clusters_from_frame`).

    When that frame is the last look's to the bit and so are the robot's spheres that reach
    the box (nothing there moved; the self-filter removes the same points), its clusters
    are the last look's: perception would give them again from the same input.
    """
    crop = look_crop(seen, params)
    if frame is None:
        frame = look_frame(sensors, seen, params)
    geometry = sensors.robot_geometry()
    arm = _spheres_in(geometry, crop)
    last = _LAST_LOOK[0] if _LAST_LOOK else None
    if (
        last is not None
        and arm is not None
        and last[2] is not None
        and last[0] == crop
        and np.array_equal(arm, last[2])
        and _same_frame(last[1], frame)
    ):
        return last[3]
    clusters = clusters_from_frame(frame, geometry, crop)
    _LAST_LOOK[:] = [(crop, frame, arm, clusters)]
    return clusters


_LAST_LOOK: list[tuple[PerceptionParams, CameraFrame, np.ndarray | None, tuple[Cluster, ...]]] = []
"""The last look: its settings, frame, the robot's spheres reaching its box and its
clusters (:func:`look`)."""


def _spheres_in(geometry: RobotGeometry, crop: PerceptionParams) -> np.ndarray | None:
    """The robot's spheres (k, 4: centre [m], radius [m]) whose bounding boxes meet the
    crop box: the only ones the self-filter can remove a point of the box with; None for a
    box in the base's frame."""
    if crop.crop_frame != "world":
        return None
    centers = np.asarray(geometry.centers, dtype=float).reshape(-1, 3)
    radii = np.asarray(geometry.radii, dtype=float).reshape(-1)
    lo, hi = np.asarray(crop.crop_min), np.asarray(crop.crop_max)
    meet = np.all((centers + radii[:, None] >= lo) & (centers - radii[:, None] <= hi), axis=1)
    return np.column_stack([centers[meet], radii[meet]])


def _same_frame(a: CameraFrame, b: CameraFrame) -> bool:
    """Two frames with the same images, intrinsics and pose, to the bit."""
    return all(
        np.array_equal(x, y)
        for x, y in (
            (a.depth, b.depth),
            (a.rgb, b.rgb),
            (a.K, b.K),
            (a.T_world_camera, b.T_world_camera),
        )
    )


def held_in_the_way(
    sensors: Sensors, seen: Cluster, params: PerceptionParams, poi: np.ndarray, reach: float
) -> bool:
    """Whether what the hand holds, within ``reach`` [m] of the ``poi`` (x, y, z, world),
    may stand between the camera and ``seen`` (its footprint's box): their images'
    rectangles meet (:func:`~smccli.perception.cloud.view_region`). A look then sees part
    of the object behind what the hand carries, which the self-filter does not remove: the
    centre of a box carried over the box it goes in moved 3-4 cm with the part it hid
    (development seed 2 of the look-alike family), though nothing moved."""
    K, T, shape, near = sensors.camera_view()
    half = float(np.hypot(*seen.extents[:2])) / 2
    top = float(seen.centroid[2] + seen.extents[2] / 2)
    lo = np.r_[seen.centroid[:2] - half, params.crop_min[2]]
    hi = np.r_[seen.centroid[:2] + half, top]
    boxes = ((lo, hi), (np.asarray(poi) - reach, np.asarray(poi) + reach))
    rects = [
        view_region(K, T, shape, near, replace(params, crop_min=tuple(a), crop_max=tuple(b)))
        for a, b in boxes
    ]
    if any(r == (0, 0, 0, 0) for r in rects):
        return False  # one of them is out of sight
    if any(r is None for r in rects):
        return True  # one of them fills the image
    (v0, v1, u0, u1), (w0, w1, x0, x1) = rects  # type: ignore[misc]
    return v0 < w1 and w0 < v1 and u0 < x1 and x0 < u1


def find_again(
    taught: Cluster, seen: Cluster, clusters: Sequence[Cluster], params: SmcParams
) -> Cluster | None:
    """The object last ``seen`` (the SMC's ``taught`` perception) among ``clusters`` of a
    frame taken while the action runs, when its goal should move; else None.

    A cluster is that object when it lies within :data:`LOOK_RADIUS` of where it was
    seen and its D_P to the taught perception is below T_hP; a whole view comes before
    one something hides part of (:attr:`Cluster.hidden`). The goal moves when the object
    has moved by more than :data:`LOOK_MOVED` (a partly hidden view:
    :data:`LOOK_MOVED_HIDDEN`, its size within :data:`LOOK_SAME_SIZE`), or when a whole
    view is clearer: the last one was partly hidden, or this one matches the taught one
    better by :data:`LOOK_BETTER`.
    """
    pp = params.perception
    hid = pp.hidden_min_points
    found = [
        (c.hidden >= hid, d, c)
        for c in clusters
        if np.hypot(*(c.centroid[:2] - seen.centroid[:2])) <= LOOK_RADIUS
        and (d := d_cluster(c, taught, pp)) < params.t_hp
    ]
    if not found:
        return None
    hidden, d, c = min(found, key=lambda f: (f[0], f[1]))  # a whole view first
    moved = float(np.hypot(*(c.centroid[:2] - seen.centroid[:2])))
    if hidden:
        # Its centre is off by what is hidden: only a larger move counts, and only with
        # the whole object in view (the arm in front of its edge, not of a third of it).
        same_size = d_extents(c.extents, seen.extents) <= LOOK_SAME_SIZE
        if moved <= LOOK_MOVED_HIDDEN or not same_size:
            return None
    elif moved <= LOOK_MOVED:
        clearer = seen.hidden >= hid or d < d_cluster(seen, taught, pp) - LOOK_BETTER
        if not clearer:
            return None
    return c


def steer(path: np.ndarray, new: np.ndarray, i: int) -> np.ndarray:
    """``path`` (n, d) already streamed up to index ``i - 1``, bent onto ``new`` (n, d), the
    same DMP rolled out to a moved goal: from ``i`` on ``new`` plus the gap at ``i - 1``,
    faded out with a min-jerk blend so the path stays smooth and ends on the new goal (the
    moving-target DMP's convergence to a moved goal, docs/dmp.md)."""
    out = path.copy()
    n = len(path)
    if i >= n:
        return out
    gap = path[i - 1] - new[i - 1]
    s = (np.arange(i, n) - (i - 1)) / (n - i)
    fade = 1.0 - min_jerk(s)
    out[i:] = new[i:] + fade[:, None] * gap
    return out
