"""A scene file's objects as MJCF bodies: boxes, cylinders, stepped pyramids, open boxes,
scales (a platform on a force sensor) and mugs (a cup and its handle), each with a free
joint unless fixed, its mass spread over its parts by volume."""

from __future__ import annotations

import math
from typing import Any

import mujoco

from smccli.world.geometry import yaw_quat
from smccli.world.specs import ObjectSpec

PYRAMID_STEPS = 3
"""A pyramid is approximated by this many stacked boxes (no meshes offline)."""

MUG_HANDLE_SPAN = 0.3
"""A mug's handle spans z = ±this × height about the centre: its top is 20 % of the height
below the rim, so the top layer perception sees is the rim alone."""
MUG_HANDLE_BAR = 0.01
"""Thickness of the handle's bars [m] (at most a third of the handle's reach)."""
MUG_HANDLE_WIDTH = 0.012
"""Width of the handle across the mug [m] (at most the body's radius)."""


def _mug_parts(sx: float, sy: float, sz: float) -> list[tuple[Any, list[float], list[float]]]:
    """A mug's primitives ``(type, half size, pos)`` from its half extents [m].

    A solid cylinder (diameter ``2 sy``) at the -x end of the bounding box, and on its +x
    side a handle reaching ``2 (sx - sy)`` out of it: a loop of three boxes (upper arm,
    outer bar, lower arm) whose top is below the rim.
    """
    box, cyl = mujoco.mjtGeom.mjGEOM_BOX, mujoco.mjtGeom.mjGEOM_CYLINDER
    r, reach = sy, 2 * (sx - sy)
    t = min(MUG_HANDLE_BAR, reach / 3)
    w = min(MUG_HANDLE_WIDTH, r) / 2
    # The arms start where their corners meet the curved wall, so they neither leave a gap
    # nor bury much volume (the mass is shared by volume) inside the body.
    x0 = sx - reach - (r - math.sqrt(r * r - w * w))
    top = MUG_HANDLE_SPAN * 2 * sz
    arm = (sx - x0) / 2
    return [
        (cyl, [r, sz, 0], [-reach / 2, 0, 0]),
        (box, [arm, w, t / 2], [x0 + arm, 0, top - t / 2]),
        (box, [t / 2, w, top - t], [sx - t / 2, 0, 0]),
        (box, [arm, w, t / 2], [x0 + arm, 0, -top + t / 2]),
    ]


def add_object(spec: mujoco.MjSpec, obj: ObjectSpec) -> None:
    """Add ``obj`` as a body of primitives; free unless ``obj.fixed``."""
    x, y, z, yaw = obj.pose
    body = spec.worldbody.add_body(name=obj.name, pos=[x, y, z], quat=yaw_quat(yaw))
    if not obj.fixed:
        body.add_freejoint(name=f"{obj.name}_joint")
    sx, sy, sz = (s / 2 for s in obj.size)
    box, cyl = mujoco.mjtGeom.mjGEOM_BOX, mujoco.mjtGeom.mjGEOM_CYLINDER
    common = dict(
        rgba=list(obj.rgba),
        condim=4,
        friction=[1.2, 0.02, 0.002],
        solref=[0.004, 1],
        solimp=[0.95, 0.99, 0.001, 0.5, 2],
    )
    parts: list[tuple[Any, list[float], list[float]]] = []  # (type, half size, pos)
    if obj.shape == "box":
        parts = [(box, [sx, sy, sz], [0, 0, 0])]
    elif obj.shape == "cylinder":
        parts = [(cyl, [sx, sz, 0], [0, 0, 0])]
    elif obj.shape == "pyramid":
        # Stacked boxes shrinking towards the top; each step a third of the height.
        h = sz * 2 / PYRAMID_STEPS
        for k in range(PYRAMID_STEPS):
            f = 1.0 - k / PYRAMID_STEPS
            parts.append((box, [sx * f, sy * f, h / 2], [0, 0, -sz + h * (k + 0.5)]))
    elif obj.shape == "mug":
        parts = _mug_parts(sx, sy, sz)
    elif obj.shape == "open_box":
        w = obj.wall / 2
        parts = [
            (box, [sx, sy, w], [0, 0, -sz + w]),
            (box, [w, sy, sz], [sx - w, 0, 0]),
            (box, [w, sy, sz], [-sx + w, 0, 0]),
            (box, [sx - 2 * w, w, sz], [0, sy - w, 0]),
            (box, [sx - 2 * w, w, sz], [0, -sy + w, 0]),
        ]
    elif obj.shape == "scale":
        # A housing (part of the static body) and a platform body on top whose force sensor
        # reads what rests on it; the platform is welded, so the reading is the static load.
        body.add_geom(
            type=box,
            size=[sx, sy, sz * 0.6],
            pos=[0, 0, -sz * 0.4],
            rgba=[0.2, 0.2, 0.22, 1],
            mass=1.0,
        )
        plat = body.add_body(name=f"{obj.name}_platform", pos=[0, 0, sz * 0.6])
        plat.add_geom(type=box, size=[sx * 0.95, sy * 0.95, sz * 0.4], mass=obj.mass, **common)
        plat.add_site(name=f"{obj.name}_site", pos=[0, 0, 0])
        spec.add_sensor(
            name=f"{obj.name}_force",
            type=mujoco.mjtSensor.mjSENS_FORCE,
            objtype=mujoco.mjtObj.mjOBJ_SITE,
            objname=f"{obj.name}_site",
        )
        return
    total = sum(
        8 * s[0] * s[1] * s[2] if t == box else math.pi * s[0] ** 2 * 2 * s[1] for t, s, _ in parts
    )
    for i, (t, half, pos) in enumerate(parts):
        vol = 8 * half[0] * half[1] * half[2] if t == box else math.pi * half[0] ** 2 * 2 * half[1]
        body.add_geom(
            name=f"{obj.name}_geom{i}",
            type=t,
            size=half,
            pos=pos,
            mass=obj.mass * vol / total,
            **common,
        )
