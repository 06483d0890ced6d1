"""A planar 2-D lidar: ``n`` beams in the horizontal plane of a site, cast with ``mj_multiRay``.

docs/design.md 9: 360 beams cost about 0.12 ms per call, cheap at 10 Hz; one ``mj_multiRay`` per
scan beats 360 rangefinder sensors evaluated on every physics step. The robot's own geoms
are left out through the geom group mask (``bodyexclude`` excludes one body, not its
children). Beams follow ``foxglove.LaserScan``:
the first at angle -pi, counter-clockwise about the site's z axis, ``2 pi / n`` apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from smccli.errors import SceneError
from smccli.world.geometry import between, wrap, yaw_of

N_GROUPS = 6
"""MuJoCo's geom groups, 0-5."""


RANGE_MAX = 8.0
"""The lidar's range [m]: beams see no further."""


@dataclass(frozen=True, slots=True)
class LidarReading:
    """One scan: ranges in the site's frame, in beam order."""

    t: float
    """Simulation time [s]."""
    ranges: np.ndarray
    """Distance along each beam [m], shape (n,); ``inf`` where nothing lies within range."""
    angle_min: float
    """Angle of the first beam about the site's z axis, from its x axis [rad] (-pi)."""
    angle_increment: float
    """Angle between beams [rad] (2 pi / n)."""
    range_max: float
    """Beams see no further than this [m]."""
    pose: np.ndarray
    """The site's planar pose in the world when the scan was taken, ``[x, y, yaw]``
    (evaluation and logs; control uses odometry)."""


class Lidar:
    """Casts the beams of one lidar site; ``ignore_group``: the geom groups it does not see
    (the robot's own, the teleop marker's)."""

    def __init__(
        self,
        model: mujoco.MjModel,
        site: str,
        *,
        beams: int = 360,
        range_max: float = RANGE_MAX,
        ignore_group: int | tuple[int, ...] | None = None,
    ) -> None:
        self.model = model
        self.site_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, site)
        if self.site_id < 0:
            raise SceneError(f"model has no lidar site {site!r}")
        if beams < 1:
            raise SceneError(f"lidar {site}: beams must be positive, found {beams}")
        self.beams = beams
        self.range_max = range_max
        self.angle_min = -math.pi
        self.angle_increment = 2 * math.pi / beams
        angles = self.angle_min + self.angle_increment * np.arange(beams)
        self._local = np.stack([np.cos(angles), np.sin(angles), np.zeros(beams)], axis=1)
        self._groups = np.ones(N_GROUPS, dtype=np.uint8)
        if ignore_group is not None:
            self._groups[list(np.atleast_1d(ignore_group))] = 0
        self._geomid = np.zeros(beams, dtype=np.int32)
        self._dist = np.zeros(beams, dtype=np.float64)

    def scan(self, data: mujoco.MjData) -> LidarReading:
        """Cast every beam from the site's current pose (``data``'s kinematics must be up to
        date, as after ``mj_step``)."""
        R = data.site_xmat[self.site_id].reshape(3, 3)
        origin = data.site_xpos[self.site_id].copy()
        vec = (self._local @ R.T).ravel()  # beam directions in the world, unit length
        mujoco.mj_multiRay(
            self.model,
            data,
            origin,
            vec,
            self._groups,
            True,
            -1,
            self._geomid,
            self._dist,
            None,
            self.beams,
            self.range_max,
        )
        ranges = self._dist.copy()
        ranges[(self._geomid < 0) | (ranges > self.range_max)] = np.inf
        yaw = yaw_of(R)
        return LidarReading(
            t=float(data.time),
            ranges=ranges,
            angle_min=self.angle_min,
            angle_increment=self.angle_increment,
            range_max=self.range_max,
            pose=np.array([origin[0], origin[1], yaw]),
        )


def lidar_mount(model: mujoco.MjModel, poi_site: str | None, lidar_site: str) -> np.ndarray:
    """Where the lidar sits on the robot: its planar pose ``[x, y, yaw]`` in the POI's frame
    [m, m, rad], from the model at its reference configuration (both sites ride the base).
    ``poi_site`` None: in the model's frame, which is a mobile manipulator's base frame at
    the reference configuration (its hand's POI does not ride the base rigidly)."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    poses = [np.zeros(3)] if poi_site is None else []
    for name in (lidar_site,) if poi_site is None else (poi_site, lidar_site):
        i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
        if i < 0:
            raise SceneError(f"model has no site {name!r}")
        poses.append(np.array([*data.site_xpos[i][:2], yaw_of(data.site_xmat[i])]))
    mount = between(*poses)
    mount[2] = wrap(mount[2])
    return mount
