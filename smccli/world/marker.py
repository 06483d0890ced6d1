"""The teleop target marker: a mocap body a person drags in MuJoCo's viewer, added to a
scene's model when recording with the keyboard operator (``Sim(target_marker=True)``)."""

from __future__ import annotations

import mujoco

from smccli.world.scene import HIDDEN_GROUP, Scene

MARKER_BODY = "smc_target"
"""The teleop target marker's body."""
MARKER_RADIUS = 0.025
"""Its sphere's radius [m]: big enough to pick with the mouse."""


def with_target_marker(scene: Scene) -> mujoco.MjModel:
    """The scene's model plus the teleop target marker: a mocap body :data:`MARKER_BODY`
    with one small sphere in geom group :data:`HIDDEN_GROUP` that collides with nothing.

    MuJoCo's viewer lets a person select a body (double-click) and move a mocap body with
    Ctrl + right drag (rotate: Ctrl + left drag), which is how the paper's interactive
    marker is dragged. A mocap body has no degrees of freedom and the geom no contacts, so
    the physics is the scene's to the bit (``tests/test_keyboard.py`` checks it); the
    sensor camera and the lidar leave the marker's group out.
    """
    spec = mujoco.MjSpec.from_string(scene.mjcf, assets=dict(scene.assets) or None)
    body = spec.worldbody.add_body(name=MARKER_BODY, mocap=True)
    body.add_geom(
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[MARKER_RADIUS, 0, 0],
        rgba=[1.0, 0.1, 0.9, 0.7],
        group=HIDDEN_GROUP,
        contype=0,
        conaffinity=0,
        mass=0.0,
    )
    return spec.compile()
