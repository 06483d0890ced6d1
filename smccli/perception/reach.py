"""The workspace crop box a scene's perception starts with, from its robot and its objects.

A scene that sets no ``perception.crop_min`` / ``crop_max`` gets the box that holds
everything its arm can touch, so that no object the arm can reach is cut:

- horizontally, the square around the disc of the arm's reach about its first joint's
  axis (:func:`arm_reach`), widened by the largest object's footprint radius (an object
  whose centre the POI reaches sticks out by that much);
- vertically, from :data:`BELOW_SUPPORT` below the lowest surface the scene's objects
  stand on (the table: the floor stays out) up to the highest the POI reaches, or the
  tallest object's top with the same margin.

The robot's own pedestal, inside that box, is removed by the self-filter
(:func:`smccli.world.robot_model.robot_body_ids`). A mobile manipulator's box rides its
base and its scene sets it.
"""

from __future__ import annotations

from smccli.world.robot import arm_reach
from smccli.world.scene import Scene

BELOW_SUPPORT = 0.05
"""The box starts this far below the lowest object's base [m]: the table plane is in it
(perception fits it), the floor is not."""
MIN_MARGIN = 0.05
"""Least horizontal margin beyond the POI's reach [m] (a scene without objects)."""

_CACHE: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {}


def workspace_box(
    scene: Scene,
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """``(crop_min, crop_max)`` [m], world frame, of an arm's scene (see the module)."""
    if scene.digest in _CACHE:
        return _CACHE[scene.digest]
    model = scene.model()
    anchor, radius = arm_reach(model, scene.robot)
    objects = scene.objects
    margin = max([MIN_MARGIN, *(o.footprint_radius for o in objects)])
    bottoms = [o.pose[2] - o.size[2] / 2 for o in objects]
    tops = [o.pose[2] + o.size[2] / 2 for o in objects]
    floor = min(bottoms) if bottoms else float(anchor[2]) - radius
    top = max([float(anchor[2]) + radius, *(t + MIN_MARGIN for t in tops)])
    half = radius + margin
    box = (
        (float(anchor[0]) - half, float(anchor[1]) - half, floor - BELOW_SUPPORT),
        (float(anchor[0]) + half, float(anchor[1]) + half, top),
    )
    lo, hi = (tuple(round(v, 4) for v in corner) for corner in box)
    _CACHE[scene.digest] = (lo, hi)  # type: ignore[assignment]
    return _CACHE[scene.digest]
