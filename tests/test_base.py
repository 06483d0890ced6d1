"""The mobile base (robot file `base`) in the rooms world, in a scene of the tests' own
(`tests/scenes/rooms_drive`, a user scene by path): driving, odometry, lidar in the log,
compile. The built-in `rooms` scene end to end: tests/test_rooms.py."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import smc

from smccli.learn.tree import load_tree
from smccli.logs import read_log
from smccli.perception import Scan2D, scan_distance
from smccli.world.geometry import wrap
from smccli.world.scene import load_scene
from smccli.world.sensors import PoiCommand
from smccli.world.sim import Sim

SCENE = Path(__file__).resolve().parent / "scenes" / "rooms_drive" / "scene.yaml"


@pytest.fixture(scope="module")
def sim() -> Sim:
    return Sim(load_scene(SCENE))


def drive(sim: Sim, x: float, y: float, yaw: float, seconds: float = 3.0) -> None:
    for _ in range(round(seconds / sim.control_period)):
        sim.step(PoiCommand(sim.t, np.array([x, y, 0.0, yaw]), 1.0))


def scan(sim: Sim) -> Scan2D:
    r = sim.lidar()
    assert r is not None
    return Scan2D(r.ranges, r.angle_min, r.angle_increment, r.range_max)


def test_base_goes_where_it_is_sent_and_odometry_says_so(sim: Sim) -> None:
    sim.reset(base_pose=np.array([0.0, 0.0, 0.0]))
    for x, y, yaw in [(0.5, 0.3, 1.0), (1.2, -0.4, -2.8), (0.8, 0.2, 3.0)]:
        start = _yaw_joint(sim)
        turn = []
        for _ in range(300):
            sim.step(PoiCommand(sim.t, np.array([x, y, 0.0, yaw]), 1.0))
            turn.append(_yaw_joint(sim))
        poi = sim.poi()
        assert math.hypot(poi[0] - x, poi[1] - y) < 0.005, poi
        assert abs(wrap(poi[3] - yaw)) < math.radians(0.5), poi
        names = sim.joint_state().names
        q = dict(zip(names, sim.joint_state().position, strict=True))
        assert (q["base_x"], q["base_y"]) == pytest.approx((x, y), abs=0.005)
        # The continuous hinge turns the short way: 1.0 -> -2.8 rad is 2.48 rad on through
        # +pi (the joint ends at 3.48), not 3.8 rad back through zero; then 3.48 -> 3.0 is
        # 0.48 rad back, not 5.8 forward. The joint ends the short turn away from where it
        # started and never strays beyond the two ends.
        short = wrap(yaw - start)
        assert turn[-1] == pytest.approx(start + short, abs=math.radians(0.5)), (start, yaw)
        lo, hi = sorted((start, start + short))
        assert lo - 0.05 < min(turn) and max(turn) < hi + 0.05, (start, yaw, min(turn), max(turn))


def _yaw_joint(sim: Sim) -> float:
    js = sim.joint_state()
    return float(dict(zip(js.names, js.position, strict=True))["base_yaw"])


def test_base_stops_at_a_wall(sim: Sim) -> None:
    sim.reset(base_pose=np.array([1.0, 0.0, 0.0]))
    drive(sim, 1.0, -3.0, 0.0)  # room 1's south wall is at y = -1.5
    assert sim.poi()[1] > -1.5 + 0.19, sim.poi()  # the chassis (0.2 m half width) is stopped


def test_lidar_tells_rooms_apart_and_never_sees_the_robot(sim: Sim) -> None:
    sim.reset(base_pose=np.array([1.0, 0.0, 0.0]))
    sim.settle(0.2)
    room1 = scan(sim)
    assert np.nanmin(room1.ranges) > 0.33  # the chassis' half diagonal: no self-hit
    sim.reset(base_pose=np.array([1.3, 0.3, 2.0]))
    sim.settle(0.2)
    room1_again = scan(sim)
    sim.reset(base_pose=np.array([4.75, 0.75, 0.5]))
    sim.settle(0.2)
    room2 = scan(sim)
    assert scan_distance(room1, room1_again) < 0.1
    assert scan_distance(room1, room2) > 0.3


@pytest.mark.slow
def test_recorded_drive_carries_the_scan_and_compiles_into_a_chain(tmp_path: Path) -> None:
    log = tmp_path / "drive.mcap"
    script = SCENE.parent / "drive.yaml"
    proc = smc("record", "--scene", SCENE, "--script", script, "-o", log)
    assert proc.returncode == 0, proc.stderr
    read = read_log(log)
    assert len(read.scans) == len(read.frames) > 50
    assert all(len(s.ranges) == 360 for s in read.scans)
    assert read.scans[0].start_angle == pytest.approx(-math.pi)
    assert read.joint_states[0].names == ("base_x", "base_y", "base_yaw")
    assert read.poi[-1][:2] == pytest.approx((5.25, 0.75), abs=0.02)
    proc = smc("compile", log, "-o", tmp_path / "tree.json")
    assert proc.returncode == 0, proc.stderr
    tree = load_tree(tmp_path / "tree.json")
    assert len(tree.edges) == 2  # two marks: the doorway, the poster
    assert {e.smc.action.goal_frame for e in tree.edges} == {"scan"}
