"""Cartesian controller: Jacobian by finite differences, tracking accuracy, reach checks."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from smccli.world.controller import CartesianController, reachable, rotation_error, wrap
from smccli.world.scene import Scene, load_scene
from smccli.world.sensors import PoiCommand
from smccli.world.sim import Sim

# Every built-in robot: the controller knows only what its robot file says.
SCENES = ("pick_place", "bench_pick_panda")


@pytest.fixture(scope="module", params=SCENES)
def scene(request: pytest.FixtureRequest) -> Scene:
    return load_scene(request.param)


@pytest.fixture(scope="module")
def model(scene: Scene) -> mujoco.MjModel:
    return scene.model()


def test_site_jacobian_matches_finite_differences(scene: Scene, model: mujoco.MjModel) -> None:
    ctl = CartesianController(model, scene.robot)
    n = len(scene.robot.arm_joints)
    rng = np.random.default_rng(0)
    eps = 1e-6
    for _ in range(5):
        q = ctl.home + rng.uniform(-0.5, 0.5, n)
        ctl._set(q)
        jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
        mujoco.mj_jacSite(model, ctl.data, jacp, jacr, ctl.site_id)
        p0 = ctl.data.site_xpos[ctl.site_id].copy()
        R0 = ctl.data.site_xmat[ctl.site_id].reshape(3, 3).copy()
        for k in range(n):
            dq = np.zeros(n)
            dq[k] = eps
            ctl._set(q + dq)
            dp = (ctl.data.site_xpos[ctl.site_id] - p0) / eps
            dr = rotation_error(ctl.data.site_xmat[ctl.site_id].reshape(3, 3), R0) / eps
            np.testing.assert_allclose(dp, jacp[:, ctl.dofadr[k]], atol=1e-5)
            np.testing.assert_allclose(dr, jacr[:, ctl.dofadr[k]], atol=1e-5)


def test_tracking_is_accurate_over_workspace_and_yaws(scene: Scene) -> None:
    """Steady state within 5 mm and 2 degrees, targets spread over the work area, any yaw."""
    sim = Sim(scene)
    rng = np.random.default_rng(1)
    for _ in range(12):
        target = np.array(
            [
                rng.uniform(0.33, 0.62),
                rng.uniform(-0.4, 0.4),
                rng.uniform(0.03, 0.3),
                rng.uniform(-math.pi, math.pi),
            ]
        )
        for _ in range(300):  # a long way round the wrist takes up to 2.5 s
            sim.step(PoiCommand(sim.t, target, 1.0))
        poi = sim.poi()
        assert np.linalg.norm(poi[:3] - target[:3]) < 0.005, (target, poi)
        assert abs(wrap(poi[3] - target[3])) < math.radians(2), (target, poi)
        R = sim.data.site_xmat[sim.poi_id].reshape(3, 3)
        assert R[2, 2] < -math.cos(math.radians(2))  # pointing down


def test_unreachable_targets_are_refused(scene: Scene, model: mujoco.MjModel) -> None:
    robot = scene.robot
    assert reachable(model, robot, np.array([0.45, 0.0, 0.1, 0.0]))
    assert not reachable(model, robot, np.array([1.3, 0.0, 0.1, 0.0]))  # too far
    assert not reachable(model, robot, np.array([0.45, 0.0, -0.05, 0.0]))  # into the table
    assert not reachable(model, robot, np.array([0.45, 0.0, 1.5, 0.0]))  # too high
    assert not reachable(model, robot, np.array([np.nan, 0.0, 0.1, 0.0]))


def test_joint_speed_is_capped(scene: Scene, model: mujoco.MjModel) -> None:
    ctl = CartesianController(model, scene.robot, max_joint_speed=1.0)
    q0 = ctl.q.copy()
    q1 = ctl.update(np.array([0.4, 0.4, 0.05, 2.0]))  # far jump
    assert np.max(np.abs(q1 - q0)) <= 0.01 + 1e-9


def test_wrap() -> None:
    assert wrap(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap(-math.pi) == pytest.approx(math.pi)
