"""Looking again without perceiving again: is the object still where it was seen?

A look (:mod:`smccli.execute.looking`) perceives its window of the image afresh: plane fit,
DBSCAN, outlines and descriptors, most of its cost. Most looks find the object where it
was. :func:`still_there` answers that from the depth image alone: the pixels around the
object's footprint (:func:`track_of`) against the frame it was perceived in. Where every
pixel that changed by more than :func:`depth_tolerance` now sees the robot (its points
inside the robot's bounding spheres, which the self-filter would remove anyway) or
something above the object (what the hand carries over it), only what is in front of the
object moved and the look is spared; anything else (a push, the camera moved) sends the
look through perception as before.

Why that leaves the look's answer unchanged: :func:`~smccli.execute.looking.find_again`
moves the goal only for an object that moved, or that a whole view sees better than a
partly hidden one. Tracking starts only from a whole view (:attr:`Cluster.hidden` under
``hidden_min_points``), and an object whose own pixels all read as before has not moved;
the arm in front of it hides part of it, which a look would have seen as a partly hidden
view that has not moved.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from smccli.perception import Cluster, PerceptionParams
from smccli.perception.cloud import points_from_depth, self_filter_mask, view_region
from smccli.world.sensors import CameraFrame, RobotGeometry

TRACK_MARGIN = 0.01
"""The window reaches this far beyond the object's footprint and top [m]: its outline
and the table along it, where a push of a millimetre shows first."""
TRACK_DEPTH_MIN = 0.001
"""A pixel has changed when its depth moved by more than this at least [m]: two renders
of one scene differ in the last bits (a window's depths against a whole frame's)."""
TRACK_DEPTH_MAX = 0.02
"""... and by more than this at most [m]: noise of a depth camera (a σ of 1-3 mm, two
frames apart) stays under it; an object pushed by a centimetre changes its outline's
pixels by its height."""

TRACK_STRAY = 4
"""Changed pixels nothing explains that still leave the object where it was: a window's
render and a whole frame's may differ at one pixel of an edge (another projection
matrix, :meth:`~smccli.world.camera.CameraRenderer.region`); a push of a centimetre
changes a band along the object's edges, tens of pixels."""


@dataclass(frozen=True, slots=True)
class Track:
    """Where an object was seen: the image window around it and the depth there in the
    frame it was perceived from."""

    region: tuple[int, int, int, int]
    """Rows and columns ``(v0, v1, u0, u1)`` of the window."""
    depth: np.ndarray
    """The reference frame's depth in the window, shape (v1 - v0, u1 - u0) float32 [m]."""
    K: np.ndarray
    """Intrinsics of the reference frame (3, 3) [px]."""
    T_world_camera: np.ndarray
    """Its camera pose (4, 4); another pose is another view."""
    tolerance: float
    """Depth change that counts [m] (:func:`depth_tolerance`)."""
    top: float
    """Height of the object's top plus :data:`TRACK_MARGIN` [m]: a changed pixel that now
    sees a point higher than this sees something in front of the object."""


def depth_tolerance(seen: Cluster) -> float:
    """Depth change that counts as a change [m]: half the object's height, within
    [:data:`TRACK_DEPTH_MIN`, :data:`TRACK_DEPTH_MAX`]; a push moves the outline's pixels
    from the object's top to the table, the object's whole height."""
    return float(np.clip(seen.extents[2] / 2, TRACK_DEPTH_MIN, TRACK_DEPTH_MAX))


def track_box(seen: Cluster, params: PerceptionParams) -> PerceptionParams:
    """``params`` with the crop box around ``seen``: its footprint's circle (any yaw) and
    its height, :data:`TRACK_MARGIN` beyond."""
    half = float(np.hypot(*seen.extents[:2])) / 2 + TRACK_MARGIN
    c, ext = np.asarray(seen.centroid, float), np.asarray(seen.extents, float)
    lo = (c[0] - half, c[1] - half, c[2] - ext[2] / 2 - TRACK_MARGIN)
    hi = (c[0] + half, c[1] + half, c[2] + ext[2] / 2 + TRACK_MARGIN)
    return replace(params, crop_min=lo, crop_max=hi, crop_frame="world")


def track_of(
    seen: Cluster, frame: CameraFrame, near: float, params: PerceptionParams
) -> Track | None:
    """The track of ``seen``, perceived in ``frame`` (camera near clipping ``near`` [m]);
    None where tracking cannot stand for a look: a partly hidden view, a crop box that
    moves with a base, or a window that is the whole image or empty."""
    if seen.hidden >= params.hidden_min_points or params.crop_frame != "world":
        return None
    depth = np.asarray(frame.depth, dtype=np.float32)
    region = view_region(frame.K, frame.T_world_camera, depth.shape, near, track_box(seen, params))
    if region is None or region[1] <= region[0] or region[3] <= region[2]:
        return None
    v0, v1, u0, u1 = region
    return Track(
        region,
        depth[v0:v1, u0:u1].copy(),
        np.array(frame.K, dtype=float),
        np.array(frame.T_world_camera, dtype=float),
        depth_tolerance(seen),
        float(seen.centroid[2] + seen.extents[2] / 2) + TRACK_MARGIN,
    )


def still_there(
    track: Track, frame: CameraFrame, robot: RobotGeometry | None, params: PerceptionParams
) -> bool:
    """Whether ``frame`` (from the same camera pose, reading at least the track's window)
    shows the tracked object where it was: each pixel of the window read in both frames
    reads within the track's tolerance of the reference, or a point in front of the
    object: inside the ``robot``'s spheres or above the object's top (what the hand
    holds); but for :data:`TRACK_STRAY` pixels."""
    if not (
        np.array_equal(frame.K, track.K)
        and np.array_equal(frame.T_world_camera, track.T_world_camera)
    ):
        return False
    v0, v1, u0, u1 = track.region
    now = np.asarray(frame.depth, dtype=np.float32)[v0:v1, u0:u1]
    ref = track.depth
    # A pixel without a reading in either frame (a depth camera's hole) tells nothing;
    # a push changes a band of the outline, most of it read.
    read = np.isfinite(now) & (now > 0) & np.isfinite(ref) & (ref > 0)
    changed = read & (np.abs(now - ref) > track.tolerance)
    n = int(np.count_nonzero(changed))
    if n <= TRACK_STRAY:
        return True
    if robot is None:
        return False
    # Lift the changed pixels alone: the others hold no reading in this copy.
    depth = np.zeros_like(np.asarray(frame.depth, dtype=np.float32))
    depth[v0:v1, u0:u1][changed] = now[changed]
    points, _ = points_from_depth(replace(frame, depth=depth), params.max_depth, track.region)
    # A reading beyond max_depth (fewer points than changes) is not the arm in front.
    if len(points) != n:
        return False
    above = points[:, 2] > track.top
    return int(np.count_nonzero(self_filter_mask(points, robot) & ~above)) <= TRACK_STRAY
