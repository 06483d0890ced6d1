"""An object's brightness relative to the table around it: what tells white from grey.

The colour histogram (:mod:`smccli.perception.histogram`) bins achromatic pixels by their
absolute brightness, and a real camera's exposure and white balance move that from one
episode to the next: a grey bar seen at a high exposure fills the same bins as a white box
seen at a low one. Their gain cancels in a ratio of two surfaces seen in the
same frame, so the object is compared with the table (the reference surface perception
already fits) around it:

    brightness = median over the object's side faces of max(R, G, B)
               / median over the table ring around it of max(R, G, B)

- **The middle of the side faces, not the top.** A white top under the lamp saturates the
  sensor (and a grey one does at the highest exposures): the ratio of two clipped tops says
  nothing. The sides are lit less and are not clipped, and they tell a white box from a
  grey bar where the tops overlap (docs/choices.md). Where too little of the sides is seen (a flat
  object, a box right under the camera) the brightness is unknown (NaN): such an object
  is taken only where none whose brightness is measured matches.
- **The table ring, not the whole table.** The lamp is a spot light: the table's brightness
  falls off from its centre, and the object is lit as the table beside it is. A ring of
  ``brightness_ring`` around the object's centre, without what lies within
  ``brightness_gap`` of the object's own points (its edge pixels mix both).

The distance term is the log-ratio (:func:`smccli.perception.distance.d_cluster`), like
the extents'. NaN where there is no table to compare with (a mobile manipulator's
shelves, a tree from before this term) or too little of the sides: the term is then left
out, and at a decision such a view ranks after the measured ones
(:func:`smccli.learn.contingency.match_stack`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from smccli.perception.params import PerceptionParams

MIN_SIDE_POINTS = 10
"""Fewer points on the middle of the side faces than this (a flat object; a box seen
from nearly above, its sides a few pixels tall and eaten by the depth camera's edge
holes): the brightness is unknown, NaN. Using all the points then (the top included)
made the grey bar near the camera brighter than the white box (1.17-1.24 against
0.91-0.98 in 6 of 300 trials' frames, issue 27); an unknown one ranks after the
objects whose brightness is measured (:func:`smccli.learn.contingency.match_stack`)."""
SIDE_BAND = (0.25, 0.75)
"""The side faces' points between these fractions of the object's height: above the
table's contact shadow and below the top's edge, where depth noise and edge holes mix
top pixels into what is below the top layer (a grey bar's 12-18 such points had a
median of 159-200 where its sides' middle had 99-120)."""
BENEATH = 0.01
"""How far in x-y from a piece's points its cluster's side faces count as beneath it
[m] (:func:`sides_beneath`): a box's side face lies within a few mm of its top's edge, and
the depth camera loses about as much along the edge."""
MIN_RING_POINTS = 50
"""Fewer table points in the ring than this (an object at the table's edge, the arm over
it): no reference, NaN."""


def side_points(heights: np.ndarray) -> np.ndarray:
    """The middle of a cluster's side faces (:data:`SIDE_BAND`), mask (n,) of its points'
    ``heights`` (n,) above the table [m]."""
    top = float(heights.max(initial=0.0))
    return (heights >= SIDE_BAND[0] * top) & (heights <= SIDE_BAND[1] * top)


def sides_beneath(
    piece: np.ndarray, cluster: np.ndarray, heights: np.ndarray, top: float
) -> np.ndarray:
    """The middle of the side faces beneath a piece of a cluster, mask (n,) of the
    cluster's points ``cluster`` (n, 3) [m] with ``heights`` (n,) above the table: those
    within :data:`BENEATH` of the piece's points ``piece`` (k, 3) in x-y, in
    :data:`SIDE_BAND` of the piece's ``top`` [m].

    A piece cut from a cluster by brightness or height may be a top alone (its sides on
    the other side of the cut), of unknown brightness: a 0.40 grey look-alike's clipped top
    then passed for the white box (development seed 8's 181). Its cluster's sides beneath
    it are its own object's: 0.44 there, the white box's top 1.15."""
    d, _ = cKDTree(piece[:, :2]).query(cluster[:, :2], distance_upper_bound=BENEATH)
    band = (heights >= SIDE_BAND[0] * top) & (heights <= SIDE_BAND[1] * top)
    return np.isfinite(d) & band


def relative_brightness(
    points: np.ndarray,
    colors: np.ndarray,
    side: np.ndarray,
    table_points: np.ndarray,
    table_colors: np.ndarray,
    params: PerceptionParams,
) -> float:
    """The brightness of a cluster's side faces over the table's around it (see above).

    ``points`` (n, 3) [m] and ``colors`` (n, 3) uint8 of the cluster, ``side`` (n,) bool
    its side faces' points (:data:`SIDE_BAND`, :func:`side_points`); ``table_points`` (m, 3) [m] and
    ``table_colors`` (m, 3) uint8 the table plane's inliers in the same frame.
    Dimensionless, > 0; NaN without a reference or without enough of the sides.
    """
    if len(table_points) == 0 or len(points) == 0:
        return float("nan")
    center = points[:, :2].mean(axis=0)
    near = np.hypot(*(table_points[:, :2] - center).T) < params.brightness_ring
    ring_xy, ring_rgb = table_points[near, :2], table_colors[near]
    if len(ring_xy) < MIN_RING_POINTS:
        return float("nan")
    gap, _ = cKDTree(points[:, :2]).query(ring_xy, distance_upper_bound=params.brightness_gap)
    ring_rgb = ring_rgb[np.isinf(gap)]  # inf: no object point within the gap
    if len(ring_rgb) < MIN_RING_POINTS:
        return float("nan")
    reference = float(np.median(ring_rgb.max(axis=1)))
    if int(side.sum()) < MIN_SIDE_POINTS:
        return float("nan")
    value = float(np.median(colors[side].max(axis=1)))
    if reference <= 0:
        return float("nan")
    return max(value, 1.0) / reference
