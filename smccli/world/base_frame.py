"""An arm's own base frame, read from its model at home: where its first joint stands,
which heading its zero points, and which way its first and last joints turn the gripper's
yaw.

The Cartesian controller (:mod:`smccli.world.controller`) takes from it the first joint's
comfortable angle for a target (the one that points the arm's home shape at it) and the
relation between the joints and the POI's yaw when the gripper points down:

    yaw = turn q_first − roll q_last + yaw_offset

``turn`` is +1 when the first joint's axis points up (it turns the yaw with it) and −1 when
down; ``roll`` +1 when the last joint's axis points along the approach axis (out of the
fingers: a positive roll turns the yaw the other way when the gripper points down) and −1
when against it. A robot whose root sits elsewhere than the world origin, turned, or with
either axis the other way round (a vendor's MJCF) is then driven as the built-in ones are.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from smccli.world.geometry import wrap, yaw_of


@dataclass(frozen=True, slots=True)
class BaseFrame:
    """The frame of an arm's first joint, in the model's world (a mobile manipulator's:
    its base joints at zero)."""

    anchor: tuple[float, float, float]
    """The first joint's anchor [m]."""
    ahead: tuple[float, float, float]
    """Unit vector normal to the first joint's axis from which bearings count [m/m]: the
    world's x made normal to the axis (y if the axis is along x)."""
    left: tuple[float, float, float]
    """The axis cross ``ahead``: bearing +pi/2 [m/m]."""
    heading: float
    """Bearing of the POI at home less the first joint's home angle: the bearing the first
    joint's zero points the arm's home shape at, wrapped [rad]."""
    turn: float
    """+1 (the first joint's axis points up) or -1 (down)."""
    roll: float
    """+1 (the last joint's axis points along the approach at home) or -1 (against it)."""
    yaw_offset: float
    """The constant of ``yaw = turn q_first - roll q_last + yaw_offset`` [rad], read at
    home (0 for the built-in arm, pi/4 for the Panda's hand)."""

    def bearing(self, x: float, y: float, z: float) -> float:
        """The first joint's angle [rad] that points the arm's home shape at the point
        ``(x, y, z)`` [m]: its bearing about the axis from the anchor, less the heading.

        For an arm at the world origin facing +x (anchor on the z axis, axis +z, heading
        0) every product below is by 1 or 0 and the result is ``atan2(y, x)`` to the bit."""
        ax, ay, az = self.anchor
        fx, fy, fz = self.ahead
        lx, ly, lz = self.left
        vx, vy, vz = x - ax, y - ay, z - az
        b = math.atan2(vx * lx + vy * ly + vz * lz, vx * fx + vy * fy + vz * fz)
        return wrap(b - self.heading) if self.heading else b


def base_frame(
    data: mujoco.MjData,
    joints: tuple[int, int],
    site_id: int,
    home: tuple[float, float],
) -> BaseFrame:
    """The base frame of the arm whose first and last joint ids are ``joints``, POI site
    ``site_id``, from ``data`` at home (its kinematics computed there: ``mj_kinematics``);
    ``home`` the first and last joints' home angles [rad]."""
    first, last = joints
    axis = data.xaxis[first].tolist()
    ax, ay, az = axis
    # World x made normal to the axis (world y for an axis along x); exact for axis +z.
    ref = (1.0, 0.0, 0.0) if abs(ax) < 0.9 else (0.0, 1.0, 0.0)
    along = ref[0] * ax + ref[1] * ay + ref[2] * az
    fx, fy, fz = ref[0] - along * ax, ref[1] - along * ay, ref[2] - along * az
    norm = math.sqrt(fx * fx + fy * fy + fz * fz)
    ahead = (fx / norm, fy / norm, fz / norm)
    left = (
        ay * ahead[2] - az * ahead[1],
        az * ahead[0] - ax * ahead[2],
        ax * ahead[1] - ay * ahead[0],
    )
    approach = data.site_xmat[site_id].reshape(3, 3)[:, 2]
    turn = 1.0 if az >= 0.0 else -1.0
    roll = 1.0 if float(np.dot(data.xaxis[last], approach)) >= 0.0 else -1.0
    x0, y0, z0 = data.xanchor[first].tolist()
    anchor = (x0, y0, z0)
    unheaded = BaseFrame(anchor, ahead, left, 0.0, turn, roll, 0.0)
    poi = data.site_xpos[site_id].tolist()
    heading = wrap(unheaded.bearing(*poi) - home[0])
    yaw = yaw_of(data.site_xmat[site_id])
    yaw_offset = wrap(yaw - (turn * home[0] - roll * home[1]))
    return BaseFrame(anchor, ahead, left, heading, turn, roll, yaw_offset)
