"""The 2-D lidar against known geometry: exact ranges in a box room, no self-hits."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from smccli.errors import SceneError
from smccli.world.lidar import Lidar

HALF_X, HALF_Y = 2.0, 1.5
"""Inner half extents of the room [m]."""

ROOM = f"""
<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <geom type="plane" size="5 5 0.1"/>
    <geom type="box" pos="{HALF_X + 0.05} 0 0.5" size="0.05 {HALF_Y + 0.1} 0.5"/>
    <geom type="box" pos="{-HALF_X - 0.05} 0 0.5" size="0.05 {HALF_Y + 0.1} 0.5"/>
    <geom type="box" pos="0 {HALF_Y + 0.05} 0.5" size="{HALF_X + 0.1} 0.05 0.5"/>
    <geom type="box" pos="0 {-HALF_Y - 0.05} 0.5" size="{HALF_X + 0.1} 0.05 0.5"/>
    <body name="robot" pos="0.3 -0.2 0" euler="0 0 0.7">
      <joint type="free"/>
      <geom type="cylinder" size="0.25 0.1" pos="0 0 0.1" group="3"/>
      <!-- an arm link right beside the lidar, in the beams' plane -->
      <geom type="box" size="0.03 0.2 0.05" pos="0.15 0 0.3" group="3"/>
      <site name="lidar" pos="0 0 0.3"/>
    </body>
  </worldbody>
</mujoco>
"""


def expected_ranges(x: float, y: float, yaw: float, angles: np.ndarray) -> np.ndarray:
    """Distance from (x, y) along world heading yaw + angle to the room's inner walls."""
    th = yaw + angles
    c, s = np.cos(th), np.sin(th)
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(c > 0, (HALF_X - x) / c, np.where(c < 0, (-HALF_X - x) / c, np.inf))
        ty = np.where(s > 0, (HALF_Y - y) / s, np.where(s < 0, (-HALF_Y - y) / s, np.inf))
    return np.minimum(tx, ty)


@pytest.fixture(scope="module")
def room() -> tuple[mujoco.MjModel, mujoco.MjData]:
    model = mujoco.MjModel.from_xml_string(ROOM)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return model, data


def test_ranges_match_the_rooms_geometry(room) -> None:
    model, data = room
    lidar = Lidar(model, "lidar", beams=360, ignore_group=3)
    reading = lidar.scan(data)
    angles = reading.angle_min + reading.angle_increment * np.arange(360)
    x, y, yaw = reading.pose
    assert (x, y, yaw) == pytest.approx((0.3, -0.2, 0.7))
    np.testing.assert_allclose(reading.ranges, expected_ranges(x, y, yaw, angles), atol=1e-6)
    assert reading.angle_min == -math.pi and reading.angle_increment == pytest.approx(
        2 * math.pi / 360
    )


def test_robot_geoms_are_never_hit(room) -> None:
    model, data = room
    ranges = Lidar(model, "lidar", ignore_group=3).scan(data).ranges
    assert ranges.min() > 0.5  # the room's nearest side, not the link 15 cm away
    seen = Lidar(model, "lidar").scan(data).ranges  # without the mask: the link is hit
    assert np.sum(seen < 0.2) > 10


def test_beyond_range_is_inf(room) -> None:
    model, data = room
    reading = Lidar(model, "lidar", range_max=1.0, ignore_group=3).scan(data)
    assert np.isinf(reading.ranges).any() and np.all(
        reading.ranges[np.isfinite(reading.ranges)] <= 1.0
    )


def test_unknown_site_is_one_line(room) -> None:
    model, _ = room
    with pytest.raises(SceneError, match="no lidar site 'laser'"):
        Lidar(model, "laser")
