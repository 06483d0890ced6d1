"""Cartesian controller: Jacobian by finite differences, tracking accuracy, reach checks."""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest

from smccli.world.controller import (
    TRACKED,
    WRIST_MARGIN,
    CartesianController,
    _svd,
    reachable,
    target_rotation,
    wrap,
)
from smccli.world.geometry import yaw_of
from smccli.world.robot import Robot, load_robot
from smccli.world.scene import Scene, load_scene
from smccli.world.sensors import PoiCommand
from smccli.world.sim import Sim


def rotation_error(R_target: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Axis-angle vector of ``R_target Rᵀ`` (world frame), shape (3,) [rad]: the reference
    the controller's own orientation error is tested against."""
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, (R_target @ R.T).ravel())
    err = np.empty(3)
    mujoco.mju_quat2Vel(err, quat, 1.0)
    return err


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


# --- the SVD solve against the pinv solve it replaced -------------------------------------


class _Reference:
    """The controller's IK as it was before the single-SVD solve (as of e39229f): damped
    step by ``numpy.linalg.solve`` on ``J Jᵀ + λ² I``, nullspace by ``numpy.linalg.pinv``.
    Kept verbatim but for ``self`` -> ``self.c`` (the model, limits and gains of ``c``) and
    the bearing and yaw signs of ``c``'s base frame (``atan2(y, x)`` and +1 at the origin)."""

    def __init__(self, c: CartesianController) -> None:
        self.c = c
        self.q = c.home.copy()
        self._q_last_goal: float | None = None
        self._jacp = np.zeros((3, c.model.nv))
        self._jacr = np.zeros((3, c.model.nv))

    def _set(self, q: np.ndarray) -> None:
        self.c.data.qpos[self.c.qadr] = q
        mujoco.mj_kinematics(self.c.model, self.c.data)
        mujoco.mj_comPos(self.c.model, self.c.data)

    def error(self, q: np.ndarray, target: np.ndarray) -> np.ndarray:
        self._set(q)
        pos = self.c.data.site_xpos[self.c.site_id]
        R = self.c.data.site_xmat[self.c.site_id].reshape(3, 3)
        return np.concatenate([target[:3] - pos, rotation_error(target_rotation(target[3]), R)])

    def ik_step(self, q: np.ndarray, target: np.ndarray, max_step: float | None) -> np.ndarray:
        c = self.c
        e = self.error(q, target)
        mujoco.mj_jacSite(c.model, c.data, self._jacp, self._jacr, c.site_id)
        J = np.vstack([self._jacp[:, c.dofadr], self._jacr[:, c.dofadr]])
        free = np.ones(len(q), dtype=bool)
        for _ in range(3):
            dq = self._step(J * free, e, q, target) * free
            pushed = ((q <= c.lo + 1e-9) & (dq < 0)) | ((q >= c.hi - 1e-9) & (dq > 0))
            if not (pushed & free).any():
                break
            free &= ~pushed
        if max_step is not None:
            biggest = np.max(np.abs(dq))
            if biggest > max_step:
                dq *= max_step / biggest
        return np.clip(q + dq, c.lo, c.hi)

    def _step(self, J: np.ndarray, e: np.ndarray, q: np.ndarray, target: np.ndarray) -> np.ndarray:
        c = self.c
        JJt = J @ J.T + c.damping**2 * np.eye(6)
        dq = J.T @ np.linalg.solve(JJt, e)
        N = np.eye(len(q)) - np.linalg.pinv(J, rcond=1e-4) @ J
        posture = c.home - q
        posture[0] = wrap(c.frame.bearing(*target[:3]) - q[0])
        if self._q_last_goal is not None:
            posture[-1] = self._q_last_goal - q[-1]
        return dq + N @ (c.nullspace_gain * posture)

    def yaw_subgoal(self, q: np.ndarray, target: np.ndarray) -> np.ndarray:
        c = self.c
        self._set(q)
        R = c.data.site_xmat[c.site_id].reshape(3, 3)
        yaw = math.atan2(R[1, 0], R[0, 0])
        d = wrap(target[3] - yaw)
        f = c.frame
        q1 = f.bearing(*target[:3])
        base = wrap(f.roll * (f.turn * q1 + f.yaw_offset - target[3]))
        branches = [base + k * 2 * math.pi for k in (-1, 0, 1)]
        inside = [b for b in branches if c.lo[-1] + 0.05 < b < c.hi[-1] - 0.05]
        q_last = min(inside or branches, key=lambda b: abs(b - q[-1]))
        self._q_last_goal = float(np.clip(q_last, c.lo[-1], c.hi[-1]))
        planned = (f.turn * q1 - f.roll * q_last) - (f.turn * q[0] - f.roll * q[-1])
        d += 2 * math.pi * round((planned - d) / (2 * math.pi))
        sub = np.array(target, dtype=float)
        sub[3] = yaw + float(np.clip(d, -0.5, 0.5))
        return sub

    def update(self, target: np.ndarray) -> np.ndarray:
        target = np.asarray(target, dtype=float)
        q = self.q
        budget = self.c.max_step
        for i in range(self.c.iterations):
            sub = self.yaw_subgoal(q, target)
            e = self.error(q, sub)  # the stopping rule is the controller's, not the solve's
            if i and np.linalg.norm(e[:3]) < TRACKED[0] and np.linalg.norm(e[3:]) < TRACKED[1]:
                break
            q_new = self.ik_step(q, sub, budget)
            budget -= float(np.max(np.abs(q_new - q)))
            q = q_new
            if budget <= 1e-9:
                break
        self.q = q
        return q

    def solve(self, target: np.ndarray, tol_pos: float = 1e-3) -> tuple[np.ndarray, bool]:
        tol_rot = math.radians(0.5)
        c = self.c
        target = np.asarray(target, dtype=float)
        q = c.home.copy()
        q[0] = np.clip(c.frame.bearing(*target[:3]), c.lo[0], c.hi[0])
        for _ in range(300):
            e = self.error(q, target)
            if np.linalg.norm(e[:3]) < tol_pos and np.linalg.norm(e[3:]) < tol_rot:
                return q, True
            q = self.ik_step(q, self.yaw_subgoal(q, target), 0.2)
        e = self.error(q, target)
        return q, bool(np.linalg.norm(e[:3]) < tol_pos and np.linalg.norm(e[3:]) < tol_rot)


AGREE = 1e-9
"""Joint targets of the SVD solve and the reference agree to this [rad] (rounding: the
differences seen are about 1e-12)."""


def _work_target(rng: np.random.Generator) -> np.ndarray:
    return np.array(
        [
            rng.uniform(0.3, 0.65),
            rng.uniform(-0.45, 0.45),
            rng.uniform(0.02, 0.35),
            rng.uniform(-math.pi, math.pi),
        ]
    )


@pytest.mark.parametrize("name", [*SCENES, "loco_manip"])
def test_ik_step_agrees_with_the_pinv_reference(name: str) -> None:
    """Random states (a fifth of the joints pushed onto a limit, so locking runs and the
    locked Jacobians lose rank) and targets: the error, the subgoal and one step agree with
    the old solve."""
    scene = load_scene(name)
    model = scene.model()
    ctl = CartesianController(model, scene.robot)
    ref = _Reference(CartesianController(model, scene.robot))
    rng = np.random.default_rng(2)
    n = len(ctl.home)
    worst = 0.0
    locked = 0
    for _ in range(150):
        q = rng.uniform(ctl.lo, ctl.hi)
        at = rng.random(n) < 0.2
        q[at] = np.where(rng.random(n) < 0.5, ctl.lo, ctl.hi)[at]
        target = _work_target(rng)
        np.testing.assert_allclose(ctl.error(q, target), ref.error(q, target), atol=1e-12)
        sub = ctl.yaw_subgoal(q, target)
        np.testing.assert_allclose(sub, ref.yaw_subgoal(q, target), atol=1e-12)
        for max_step in (None, 0.2, 0.025):
            new, old = ctl.ik_step(q, sub, max_step), ref.ik_step(q, sub, max_step)
            worst = max(worst, float(np.max(np.abs(new - old))))
        locked += bool(at.any())
    assert worst < AGREE, worst
    assert locked > 50


def test_singular_jacobians_agree_with_the_pinv_reference() -> None:
    """The arm stretched straight up (joints 1, 3, 5 and 7 on one axis): J has rank 4, the
    pinv truncation decides the nullspace, and the step still agrees."""
    scene = load_scene("pick_place")
    model = scene.model()
    ctl = CartesianController(model, scene.robot)
    ref = _Reference(CartesianController(model, scene.robot))
    rng = np.random.default_rng(4)
    for _ in range(20):
        q = rng.uniform(ctl.lo, ctl.hi)
        q[[1, 3, 5]] = 0.0
        ctl._set(q)
        jac = np.zeros((6, model.nv))
        mujoco.mj_jacSite(model, ctl.data, jac[:3], jac[3:], ctl.site_id)
        s = np.linalg.svd(jac[:, ctl.dofadr], compute_uv=False)
        assert s[-1] < 1e-4 * s[0]
        target = _work_target(rng)
        sub = ctl.yaw_subgoal(q, target)
        ref.yaw_subgoal(q, target)
        assert np.max(np.abs(ctl.ik_step(q, sub, None) - ref.ik_step(q, sub, None))) < AGREE


@pytest.mark.parametrize("name", [*SCENES, "loco_manip"])
def test_control_ticks_and_full_ik_agree_with_the_pinv_reference(name: str) -> None:
    """Closed loop: 600 control ticks towards targets that jump every 60 ticks (joint
    targets compared every tick), then the full IK on random targets, reachable or not."""
    scene = load_scene(name)
    model = scene.model()
    ctl = CartesianController(model, scene.robot)
    ref = _Reference(CartesianController(model, scene.robot))
    rng = np.random.default_rng(3)
    worst = 0.0
    target = _work_target(rng)
    for tick in range(600):
        if tick % 60 == 0:
            target = _work_target(rng)
        worst = max(worst, float(np.max(np.abs(ctl.update(target) - ref.update(target)))))
    assert worst < AGREE, worst
    verdicts = []
    for _ in range(6):
        target = _work_target(rng) * [1.4, 1.4, 1.0, 1.0]  # some beyond reach
        (q_new, ok_new), (q_old, ok_old) = ctl.solve(target), ref.solve(target)
        assert ok_new == ok_old
        assert np.max(np.abs(q_new - q_old)) < AGREE
        verdicts.append(ok_new)
    assert any(verdicts)


# --- the control tick on Python floats against its array form ------------------------------


class _ArrayForm:
    """A control tick as array formulas, the controller's own before its hot path moved to
    Python floats and views (as of 01c76bd); kept verbatim but for ``self`` -> ``self.c``
    and the bearing and yaw signs of ``c``'s base frame (``atan2(y, x)`` and +1 at the origin).
    The controller promises the same operations in the same order: the same bits."""

    def __init__(self, c: CartesianController) -> None:
        self.c = c
        self.q = c.home.copy()
        self.goal: float | None = None  # the last joint's branch
        self.locked = 0  # ticks that locked a joint at a limit

    def update(self, target: np.ndarray) -> np.ndarray:
        c, q, budget = self.c, self.q, self.c.max_step
        for i in range(c.iterations):
            c._set(q)
            sub = self.yaw_subgoal(q, target)
            e = self.error(sub)
            if i and e[:3] @ e[:3] < TRACKED[0] ** 2 and e[3:] @ e[3:] < TRACKED[1] ** 2:
                break
            q_new = self.ik_step(q, sub, budget, e)
            budget -= float(np.abs(q_new - q).max())
            q = q_new
            if budget <= 1e-9:
                break
        self.q = q
        return q

    def error(self, target: np.ndarray) -> np.ndarray:
        c = self.c
        e = np.zeros(6)
        np.subtract(target[:3], c.data.site_xpos[c.site_id], out=e[:3])
        co, s = math.cos(target[3]), math.sin(target[3])
        R_target = np.array([[co, s, 0.0], [s, -co, 0.0], [0.0, 0.0, -1.0]])
        R_err, quat = np.zeros((3, 3)), np.zeros(4)
        mujoco.mju_mulMatMatT(R_err, R_target, c.data.site_xmat[c.site_id].reshape(3, 3))
        mujoco.mju_mat2Quat(quat, R_err.ravel())
        mujoco.mju_quat2Vel(e[3:], quat, 1.0)
        return e

    def yaw_subgoal(self, q: np.ndarray, target: np.ndarray) -> np.ndarray:
        c = self.c
        yaw = yaw_of(c.data.site_xmat[c.site_id])
        x, y, _, target_yaw = target.tolist()
        q_first, q_last_now = q[0].item(), q[-1].item()
        d = wrap(target_yaw - yaw)
        f = c.frame
        q1 = f.bearing(x, y, target[2])
        base = wrap(f.roll * (f.turn * q1 + f.yaw_offset - target_yaw))
        branches = [base + k * 2 * math.pi for k in (-1, 0, 1)]
        lo, hi = float(c.lo[-1]), float(c.hi[-1])
        inside = [b for b in branches if lo + WRIST_MARGIN < b < hi - WRIST_MARGIN]
        q_last = min(inside or branches, key=lambda b: abs(b - q_last_now))
        self.goal = min(max(q_last, lo), hi)
        planned = (f.turn * q1 - f.roll * q_last) - (f.turn * q_first - f.roll * q_last_now)
        d += 2 * math.pi * round((planned - d) / (2 * math.pi))
        sub = np.array(target, dtype=float)
        sub[3] = yaw + min(max(d, -0.5), 0.5)
        return sub

    def ik_step(
        self, q: np.ndarray, target: np.ndarray, max_step: float, e: np.ndarray
    ) -> np.ndarray:
        c = self.c
        jac = np.zeros((6, c.model.nv))
        mujoco.mj_jacSite(c.model, c.data, jac[:3], jac[3:], c.site_id)
        J = jac[:, c.dofadr]
        posture = c.home - q
        posture[0] = wrap(c.frame.bearing(*target[:3].tolist()) - q[0])
        if self.goal is not None:
            posture[-1] = self.goal - q[-1]
        pull = c.nullspace_gain * posture
        dq = self.step(J, e, pull)
        at_lo, at_hi = q <= c.lo + 1e-9, q >= c.hi - 1e-9
        if (at_lo | at_hi).any():
            self.locked += 1
            free = np.ones(len(q), dtype=bool)
            for _ in range(2):
                pushed = (at_lo & (dq < 0)) | (at_hi & (dq > 0))
                if not (pushed & free).any():
                    break
                free &= ~pushed
                dq = self.step(J * free, e, pull) * free
        biggest = max(dq.max(), -dq.min())
        if biggest > max_step:
            dq *= max_step / biggest
        dq += q
        return dq.clip(c.lo, c.hi, out=dq)

    def step(self, J: np.ndarray, e: np.ndarray, pull: np.ndarray) -> np.ndarray:
        u, s, vt = _svd(J)
        c = s / (s * s + self.c.damping**2) * (e @ u)
        c -= (vt @ pull) * (s > 1e-4 * s[0])
        return pull + c @ vt


@pytest.mark.parametrize("name", [*SCENES, "loco_manip"])
def test_control_ticks_are_bit_identical_to_the_array_form(name: str) -> None:
    """1200 control ticks, the target jumping every 60, the arm restarted every 300 from
    random postures with joints on their limits (the locking path runs): every joint
    target has the bits of the array form's."""
    scene = load_scene(name)
    model = scene.model()
    ctl = CartesianController(model, scene.robot)
    ref = _ArrayForm(CartesianController(model, scene.robot))
    rng = np.random.default_rng(5)
    target = _work_target(rng)
    for tick in range(1200):
        if tick % 300 == 150:
            q = rng.uniform(ctl.lo, ctl.hi)
            q[::3] = np.where(rng.random(len(q)) < 0.5, ctl.lo, ctl.hi)[::3]
            ctl.reset(q)
            ref.q, ref.goal = q.copy(), None
        if tick % 60 == 0:
            target = _work_target(rng)
        new, old = ctl.update(target), ref.update(target)
        assert np.array_equal(new, old), (tick, new - old)
        if tick % 97 == 0:  # another method moves the controller's kinematics meanwhile
            ctl.forward(rng.uniform(ctl.lo, ctl.hi))
    assert ref.locked > 20, ref.locked


def _last_joint(sim: Sim) -> int:
    return list(sim.joint_state().names).index(sim.robot.arm_joints[-1])


def _yaw_travel(sim: Sim, target: np.ndarray, seconds: float = 3.0) -> float:
    """Stream ``target`` for ``seconds``; how far the POI's yaw travelled [rad]."""
    travel, last = 0.0, sim.poi()[3]
    for _ in range(round(seconds / sim.control_period)):
        sim.step(PoiCommand(sim.t, target, 1.0))
        yaw = sim.poi()[3]
        travel += abs(wrap(yaw - last))
        last = yaw
    return travel


def test_a_goal_yaw_past_the_wrist_limit_is_taken_by_its_equivalent(
    scene: Scene, model: mujoco.MjModel
) -> None:
    """A goal whose yaw the wrist reaches the short way only past its limit makes the hand
    turn the long way round, nearly a full turn (a held box spun an open box with it,
    issue 27); ``goal_from_object`` with the controller's ``yaw_ok`` takes the yaw the
    gripper's half-turn symmetry makes equivalent, and the hand turns less than a half."""
    from smccli.learn.frames import goal_from_object
    from smccli.perception import Cluster

    ctl = CartesianController(model, scene.robot)
    hi = float(ctl.hi[-1])

    def yaw_for(xy: tuple[float, float], wrist: float) -> float:
        """The yaw that puts the last joint at ``wrist`` over ``xy``, pointing down."""
        return wrap(ctl.wrist_short_way(np.array([*xy, 0.1, 0.0]), wrist) - wrist)

    start = np.array([0.43, 0.10, 0.15, yaw_for((0.43, 0.10), hi - 0.3)])
    box = Cluster(
        centroid=np.array([0.44, 0.30, 0.035]),
        yaw=0.0,
        yaw_period=math.pi,
        extents=np.array([0.26, 0.16, 0.07]),
        histogram=np.full(8, 1 / 8),
        n_points=500,
    )
    # A place goal over the box whose nearest yaw puts the wrist 0.6 rad past its limit.
    goal_obj = np.array([0.0, 0.0, 0.075, yaw_for((0.44, 0.30), hi + 0.6)])
    travel = {}
    for name in ("nearest", "chosen"):
        sim = Sim(scene)
        try:
            # Turn the wrist there continuously, as a demonstrated motion would.
            w0 = float(sim.joint_state().position[_last_joint(sim)])
            for w in np.linspace(w0, hi - 0.3, 200):
                sim.step(PoiCommand(sim.t, np.r_[start[:3], yaw_for((0.43, 0.10), w)], 1.0))
            _yaw_travel(sim, start, 1.0)
            q_last = float(sim.joint_state().position[_last_joint(sim)])
            assert abs(q_last - (hi - 0.3)) < 0.05
            ok = lambda g, w=q_last: ctl.wrist_inside(ctl.wrist_short_way(g, w))  # noqa: E731
            nearest = goal_from_object(goal_obj, box, near_yaw=sim.poi()[3])
            chosen = goal_from_object(goal_obj, box, near_yaw=sim.poi()[3], yaw_ok=ok)
            assert not ok(nearest) and ok(chosen)
            assert abs(abs(wrap(chosen[3] - nearest[3])) - math.pi) < 1e-9
            np.testing.assert_allclose(chosen[:3], nearest[:3], atol=1e-12)  # the same place
            travel[name] = _yaw_travel(sim, nearest if name == "nearest" else chosen)
        finally:
            sim.close()
    assert travel["chosen"] < math.pi
    assert travel["nearest"] > 1.5 * math.pi, travel


# --- the controller in the arm's own base frame ------------------------------------------------


def _arm(
    name: str,
    turn: float = 0.0,
    shift: tuple[float, float, float] = (0.0, 0.0, 0.0),
    flip: str = "",
) -> tuple[mujoco.MjModel, Robot]:
    """The built-in robot ``name`` alone, its root body turned by ``turn`` [rad] about z and
    moved by ``shift`` [m]; ``flip`` ("first", "last" or "") names an arm joint whose axis
    is reversed, its range and home angle mirrored (the same arm, its joint counted the
    other way round)."""
    robot = load_robot(name)
    spec = mujoco.MjSpec.from_file(str(robot.mjcf_path))
    root = spec.worldbody.first_body()
    root.pos = shift
    root.quat = [math.cos(turn / 2), 0.0, 0.0, math.sin(turn / 2)]
    home = list(robot.home)
    if flip:
        i = 0 if flip == "first" else len(home) - 1
        joint = spec.joint(robot.arm_joints[i])
        joint.axis = -joint.axis
        joint.range = [-joint.range[1], -joint.range[0]]
        home[i] = -home[i]
    return spec.compile(), dataclasses.replace(robot, home=tuple(home))


def _reach(ctl: CartesianController, target: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Joint targets after 300 control ticks towards ``target`` from home, and the POI's
    position [m] and yaw [rad] errors there."""
    ctl.reset(ctl.home)
    for _ in range(300):
        ctl.update(target)
    poi = ctl.forward(ctl.q)
    return ctl.q.copy(), float(np.linalg.norm(poi[:3] - target[:3])), abs(wrap(poi[3] - target[3]))


@pytest.mark.parametrize("name", ["arm", "panda"])
@pytest.mark.parametrize(
    ("turn", "shift", "flip"),
    [
        (math.pi, (0.3, -0.2, 0.05), ""),  # a vendor's base, turned half a turn and moved
        (0.7, (-0.1, 0.4, 0.0), ""),
        (0.0, (0.0, 0.0, 0.0), "last"),  # the wrist roll's axis into the flange
        (math.pi, (0.3, -0.2, 0.05), "first"),  # the base joint's axis downwards
    ],
)
def test_an_arm_moved_turned_or_with_an_axis_reversed_tracks_as_the_original(
    name: str, turn: float, shift: tuple[float, float, float], flip: str
) -> None:
    """Targets of the work area (any yaw), moved with the arm's root: the same joint
    targets tick by tick, up to rounding (the reversed joint's negated), and the same
    accuracy as the arm at the origin."""
    model, robot = _arm(name)
    moved_model, moved_robot = _arm(name, turn, shift, flip)
    ctl, moved = CartesianController(model, robot), CartesianController(moved_model, moved_robot)
    sign = np.ones(len(robot.home))
    if flip:
        sign[0 if flip == "first" else -1] = -1.0
    c, s = math.cos(turn), math.sin(turn)
    rng = np.random.default_rng(6)
    for _ in range(6):
        target = _work_target(rng)
        x, y, z, yaw = target
        moved_target = np.array(
            [c * x - s * y + shift[0], s * x + c * y + shift[1], z + shift[2], wrap(yaw + turn)]
        )
        q, pos, rot = _reach(ctl, target)
        moved_q, moved_pos, moved_rot = _reach(moved, moved_target)
        assert pos < 1e-3 and rot < math.radians(0.5), (target, pos, rot)
        assert moved_pos < 1e-3 and moved_rot < math.radians(0.5), (
            moved_target,
            moved_pos,
            moved_rot,
        )
        np.testing.assert_allclose(moved_q, sign * q, atol=1e-6)


@pytest.mark.parametrize("name", ["arm", "panda"])
def test_the_base_frame_of_an_arm_at_the_origin_is_the_world(name: str) -> None:
    """The built-in arms stand at the origin facing +x, both axes the promised way: the
    bearing is ``atan2(y, x)`` to the bit (their joint targets keep their bits)."""
    model, robot = _arm(name)
    frame = CartesianController(model, robot).frame
    assert (frame.heading, frame.turn, frame.roll) == (0.0, 1.0, 1.0)
    rng = np.random.default_rng(7)
    for x, y, z, _ in (_work_target(rng) * [1, 1, 3, 1] for _ in range(200)):
        assert frame.bearing(x, y, z) == math.atan2(y, x)
    moved = CartesianController(*_arm(name, math.pi, (0.3, -0.2, 0.05), "last")).frame
    assert (moved.turn, moved.roll) == (1.0, -1.0)
    assert abs(abs(moved.heading) - math.pi) < 1e-9
    np.testing.assert_allclose(moved.anchor[:2], [0.3, -0.2], atol=1e-12)
