"""Cartesian controller: a POI target ``[x, y, z, yaw]`` (gripper pointing down) to joint targets.

Damped least squares on ``mj_jacSite`` (position and orientation), with a nullspace pull
towards a comfortable posture:

    dq = Jᵀ (J Jᵀ + λ² I)⁻¹ e  +  (I − J⁺ J) k (q_home − q)

where ``e`` stacks the position error [m] and the orientation error (axis-angle, world
frame) [rad]. The controller solves on its own ``MjData`` (kinematics only) from the last
joint target, so the position servos receive a consistent, smooth target and the robot's
dynamics (sag, contacts) never feed back into the IK. The same controller serves teleop
and replay.

Both terms come from one thin SVD ``J = U Σ Vᵀ`` (``J`` is 6 x n): the damped step is
``V Σ (Σ² + λ²)⁻¹ Uᵀ e`` and ``J⁺ J = V_r V_rᵀ`` over the singular values above
``1e-4 σ_max`` (the truncation of ``numpy.linalg.pinv(J, rcond=1e-4)``). It runs up to
three times per control period (until the POI is within :data:`TRACKED`) and is a
campaign's hot path, so it calls LAPACK directly, reuses buffers and views, and computes
the short vectors on Python floats (see :class:`CartesianController`).
"""

from __future__ import annotations

import math
import operator

import mujoco
import numpy as np
from scipy.linalg import lapack

from smccli.errors import SceneError
from smccli.world.base_frame import BaseFrame, base_frame
from smccli.world.geometry import TWO_PI, wrap, yaw_of
from smccli.world.robot import Robot

# Flip so that the POI z axis points down; the yaw then rotates about world z.
ARRIVAL_TOLERANCE = 0.005
"""A move has arrived once the POI is this close to its target [m]: the scripted operator's
moves and the executor's hold after a rollout end there."""

_DOWN = np.diag([1.0, -1.0, -1.0])
_RCOND = 1e-4
"""Singular values of ``J`` below this fraction of the largest are zero in ``J⁺``."""
_AT_LIMIT = 1e-9
"""A joint this close to a limit [rad] is at it."""
WRIST_MARGIN = 0.05
"""The wrist roll (the last joint) keeps this far inside its limits [rad]: a yaw it would
reach only beyond is reached the long way round (:meth:`CartesianController.yaw_subgoal`)."""
TRACKED = (1e-4, 1e-3)
"""Within this of its target, position [m] and orientation [rad], a control period's
POI needs no further IK iteration: further ones refine far below what the position servos
track (mm)."""


def target_rotation(yaw: float) -> np.ndarray:
    """POI orientation for a gripper pointing down at ``yaw`` [rad], shape (3, 3)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ _DOWN


def poi_pose(data: mujoco.MjData, site_id: int) -> np.ndarray:
    """POI ``[x, y, z, yaw]`` from a site's pose; yaw is that of the site's x axis."""
    return np.array([*data.site_xpos[site_id], yaw_of(data.site_xmat[site_id])])


def _svd(J: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thin SVD ``U, σ, Vᵀ`` of ``J`` (m x n): shapes (m, k), (k,), (k, n), k = min(m, n).

    LAPACK's ``gesdd`` called directly (numpy's wrapper costs twice the decomposition of
    a 6 x 7 matrix); numpy's SVD, which raises on failure, if it does not converge."""
    u, s, vt, info = lapack.dgesdd(J, compute_uv=1, full_matrices=0)
    if info != 0:
        u, s, vt = np.linalg.svd(J, full_matrices=False)
    return u, s, vt


def _span(adr: np.ndarray) -> slice | np.ndarray:
    """``adr`` as a slice when the addresses are consecutive (indexing gives a view)."""
    first, n = int(adr[0]), len(adr)
    return slice(first, first + n) if np.array_equal(adr, np.arange(first, first + n)) else adr


class CartesianController:
    """Turns POI targets into arm joint targets, one control tick at a time.

    Built from a :class:`~smccli.world.robot.Robot`: its arm joints (base to flange), POI
    site and home posture (the nullspace pulls towards it). The yaw heuristics work in the
    arm's own base frame (:mod:`smccli.world.base_frame`, read from the model at home):
    they assume what the robot file promises, that the first joint turns about the
    vertical (up or down) and the last rolls the gripper when it points down (its axis
    along the approach or against it), wherever the arm's root stands and faces.

    A control tick is some sixty calls on vectors of at most 7 entries, where a numpy
    call costs more than its arithmetic: the hot path (:meth:`update`) keeps numpy, LAPACK
    and MuJoCo for the products, the SVD and the kinematics, does the elementwise rest on
    Python floats, reads the site pose through views made once and skips the kinematics
    the last tick left at the same joints. Every floating-point operation is the one of
    the array formulas (the docstrings'), in the same order: the joint targets have the
    same bits whichever form computes them (tests/test_controller.py holds the array form).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        robot: Robot,
        *,
        damping: float = 0.03,
        nullspace_gain: float = 0.2,
        max_joint_speed: float = 2.5,
        control_period: float = 0.01,
        iterations: int = 3,
    ) -> None:
        self.model = model
        self.data = mujoco.MjData(model)  # scratch: kinematics for the IK only
        self.site_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, robot.poi)
        if self.site_id < 0:
            raise SceneError(f"robot {robot.name}: model has no POI site {robot.poi!r}")
        jids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in robot.arm_joints]
        if min(jids) < 0:
            raise SceneError(
                f"robot {robot.name}: model lacks the arm joints {', '.join(robot.arm_joints)}"
            )
        self.home = robot.home_array()
        """Home posture, shape (n,) [rad]."""
        self.qadr = np.array([model.jnt_qposadr[j] for j in jids])
        self.dofadr = np.array([model.jnt_dofadr[j] for j in jids])
        self.lo = model.jnt_range[jids, 0].copy()
        self.hi = model.jnt_range[jids, 1].copy()
        self.damping = damping
        self._damping2 = damping**2
        self.nullspace_gain = nullspace_gain
        self.max_step = max_joint_speed * control_period
        self.iterations = iterations
        self.q = self.home.copy()
        """Current joint target, shape (n,) [rad]."""
        self._buffers()
        self._set(self.home)
        self.frame: BaseFrame = base_frame(
            self.data, (jids[0], jids[-1]), self.site_id, (self.home[0], self.home[-1])
        )
        """The arm's base frame: the first joint's comfortable angle for a target and how
        the first and last joints turn the POI's yaw."""
        self._turn, self._roll = self.frame.turn, self.frame.roll
        self._yaw_offset = self.frame.yaw_offset
        self._q_last_goal: float | None = None

    def _buffers(self) -> None:
        """Buffers and views of the hot path, made once: MjData's arrays stay where they
        are, and a view costs as much to make as the arithmetic on it."""
        self._qpos = _span(self.qadr)
        self._dofs = _span(self.dofadr)
        qpos = self.data.qpos[self._qpos]
        self._qpos_view = qpos if isinstance(self._qpos, slice) else None
        self._lo_tol = self.lo + _AT_LIMIT
        self._hi_tol = self.hi - _AT_LIMIT
        self._last_lo, self._last_hi = float(self.lo[-1]), float(self.hi[-1])
        self._wrist_lo, self._wrist_hi = self._last_lo + WRIST_MARGIN, self._last_hi - WRIST_MARGIN
        self._home_list = self.home.tolist()
        self._lo_list, self._hi_list = self.lo.tolist(), self.hi.tolist()
        self._lo_tol_list, self._hi_tol_list = self._lo_tol.tolist(), self._hi_tol.tolist()
        self._jac = np.zeros((6, self.model.nv))
        """Site Jacobian, position rows then rotation rows, shape (6, nv)."""
        self._jacp, self._jacr = self._jac[:3], self._jac[3:]
        self._jac_arm = self._jac[:, self._dofs] if isinstance(self._dofs, slice) else None
        self._e = np.zeros(6)
        self._e_pos, self._e_rot = self._e[:3], self._e[3:]
        self._R_target = np.zeros((3, 3))
        self._R_target[2, 2] = -1.0
        self._R_err = np.zeros((3, 3))
        self._R_err_flat = self._R_err.reshape(9)
        self._quat = np.zeros(4)
        self._sub = np.zeros(4)
        self._site_xpos = self.data.site_xpos[self.site_id]
        self._site_xmat = self.data.site_xmat[self.site_id]
        self._site_R = self._site_xmat.reshape(3, 3)
        self._placed = b""
        """The bytes of the joint positions :meth:`update` left the kinematics at ("" when
        another method moved them since)."""

    def reset(self, q: np.ndarray) -> None:
        """Restart from joint positions ``q``, shape (n,) [rad]; forgets the yaw branch (as a
        new controller would: :meth:`update` chooses one before it uses it)."""
        self.q = np.clip(np.asarray(q, dtype=float), self.lo, self.hi)
        self._q_last_goal = None

    def forward(self, q: np.ndarray) -> np.ndarray:
        """POI ``[x, y, z, yaw]`` at joint positions ``q`` (forward kinematics)."""
        self._set(q)
        return poi_pose(self.data, self.site_id)

    def _place(self, q: np.ndarray) -> None:
        """Forward kinematics (poses) at ``q``; :meth:`_set` adds what the Jacobian needs."""
        if self._qpos_view is None:
            self.data.qpos[self._qpos] = q
        else:
            self._qpos_view[:] = q
        mujoco.mj_kinematics(self.model, self.data)
        self._placed = b""

    def _set(self, q: np.ndarray) -> None:
        self._place(q)
        mujoco.mj_comPos(self.model, self.data)

    def error(self, q: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Task error at ``q``: position [m] and orientation [rad], shape (6,)."""
        self._set(q)
        return self._error(np.asarray(target, dtype=float)).copy()

    def _error(self, target: np.ndarray) -> np.ndarray:
        """:meth:`error` at the kinematics last set, into a buffer."""
        np.subtract(target[:3], self._site_xpos, out=self._e_pos)
        self._rotation_error(float(target[3]))
        return self._e

    def _rotation_error(self, yaw: float) -> None:
        """The orientation error towards :func:`target_rotation` (``yaw``), written out,
        into the error buffer's last three entries."""
        c, s = math.cos(yaw), math.sin(yaw)
        R_target = self._R_target  # Rz(yaw) @ _DOWN, the zeros and -1 set once
        R_target[0, 0], R_target[0, 1], R_target[1, 0], R_target[1, 1] = c, s, s, -c
        mujoco.mju_mulMatMatT(self._R_err, R_target, self._site_R)
        mujoco.mju_mat2Quat(self._quat, self._R_err_flat)
        mujoco.mju_quat2Vel(self._e_rot, self._quat, 1.0)

    def ik_step(self, q: np.ndarray, target: np.ndarray, max_step: float | None) -> np.ndarray:
        """One damped-least-squares step from ``q`` towards ``target``; returns the new q."""
        self._set(q)
        return self._ik_step(q, np.asarray(target, dtype=float), max_step)

    def _ik_step(
        self,
        q: np.ndarray,
        target: np.ndarray,
        max_step: float | None,
        e: np.ndarray | None = None,
    ) -> np.ndarray:
        """:meth:`ik_step` at the kinematics last set (those of ``q``), ``e`` the error
        there if known."""
        if e is None:
            e = self._error(target)
        x, y, z = target[:3].tolist()
        return self._advance(q, q.tolist(), self.frame.bearing(x, y, z), max_step, e)

    def _advance(
        self,
        q: np.ndarray,
        q_list: list[float],
        bearing: float,
        max_step: float | None,
        e: np.ndarray,
    ) -> np.ndarray:
        """The IK step from ``q`` (also as ``q_list``) at the kinematics and Jacobian inputs
        last set, ``bearing`` the first joint's comfortable angle for the target
        (:meth:`~smccli.world.base_frame.BaseFrame.bearing`) [rad], ``e`` the error."""
        mujoco.mj_jacSite(self.model, self.data, self._jacp, self._jacr, self.site_id)
        J = self._jac[:, self._dofs] if self._jac_arm is None else self._jac_arm
        # Nullspace: keep the elbow and the redundant rolls near the home posture. The base
        # yaw's comfortable value points the arm at the target, the last joint's is the
        # branch :meth:`yaw_subgoal` chose for the target's yaw.
        k = self.nullspace_gain
        pull_list = [k * (h - qi) for h, qi in zip(self._home_list, q_list, strict=True)]
        pull_list[0] = k * wrap(bearing - q_list[0])
        if self._q_last_goal is not None:
            pull_list[-1] = k * (self._q_last_goal - q_list[-1])
        pull = np.array(pull_list)
        dq = self._step(J, e, pull)
        # A joint at a limit that the step pushes further would have its share clipped away
        # and the error would stay (the Panda's wrist roll, 5.8 rad of travel, stalled 0.4
        # rad short): lock it for this step so the other joints take the error up.
        if any(map(operator.le, q_list, self._lo_tol_list)) or any(
            map(operator.ge, q_list, self._hi_tol_list)
        ):
            at_lo, at_hi = q <= self._lo_tol, q >= self._hi_tol
            free = np.ones(len(q), dtype=bool)
            for _ in range(2):
                pushed = (at_lo & (dq < 0)) | (at_hi & (dq > 0))
                if not (pushed & free).any():
                    break
                free &= ~pushed
                dq = self._step(J * free, e, pull) * free
        if max_step is not None:
            dq_list = dq.tolist()
            biggest = max(max(dq_list), -min(dq_list))
            if biggest > max_step:
                dq *= max_step / biggest
        dq += q
        return dq.clip(self.lo, self.hi, out=dq)

    def _step(self, J: np.ndarray, e: np.ndarray, pull: np.ndarray) -> np.ndarray:
        """Damped least squares on ``J`` plus the posture ``pull`` in its nullspace.

        Exact projector (not the damped one), so the posture pull leaves no task error.
        In the right singular basis: ``c = Σ(Σ² + λ²)⁻¹ Uᵀ e − m ⊙ (Vᵀ pull)``, ``m`` one
        where σ is above the truncation (σ sorted descending, so σ_max = σ[0]), and the
        step is ``pull + V c``; the length-k vectors go through Python floats."""
        u, s, vt = _svd(J)
        sigma = s.tolist()
        cut, damping2 = _RCOND * sigma[0], self._damping2
        c = [
            si / (si * si + damping2) * a - b * (si > cut)
            for si, a, b in zip(sigma, e.dot(u).tolist(), vt.dot(pull).tolist(), strict=True)
        ]
        return pull + np.array(c).dot(vt)

    def yaw_subgoal(self, q: np.ndarray, target: np.ndarray) -> np.ndarray:
        """``target`` with its yaw replaced by a waypoint at most 0.5 rad from the current yaw.

        The orientation error alone always turns the short way, which can drive the wrist
        roll into its limit. Pointing down in the home posture's shape, yaw = turn q_first
        − roll q_last + offset (:class:`~smccli.world.base_frame.BaseFrame`: turn and roll
        are +1 when the first joint turns the yaw with it and the last one against it);
        with q_first settling at the target's bearing (the angle that points the arm at
        it, :meth:`~smccli.world.base_frame.BaseFrame.bearing`), pick the q_last branch
        inside the limits closest to the current q_last and turn the way that leads there.
        That branch is also where the posture pull takes q_last (:meth:`_step`), so the
        redundant joints do not wind up to trade the last joint's travel for theirs.
        """
        self._set(q)
        return self._yaw_subgoal(q, np.asarray(target, dtype=float)).copy()

    def _yaw_subgoal(self, q: np.ndarray, target: np.ndarray) -> np.ndarray:
        """:meth:`yaw_subgoal` at the kinematics last set (those of ``q``), into a buffer."""
        x, y, z, target_yaw = target.tolist()
        sub = self._sub
        sub[:] = target
        sub[3] = self._subgoal_yaw(
            q[0].item(), q[-1].item(), target_yaw, self._aim(x, y, z, target_yaw)
        )
        return sub

    def _aim(self, x: float, y: float, z: float, target_yaw: float) -> tuple[float, list[float]]:
        """What :meth:`yaw_subgoal` takes from the target alone: its bearing [rad] and the
        last joint's branches for its yaw, those inside the limits if any [rad]."""
        q1 = self.frame.bearing(x, y, z)
        base = wrap(self._roll * (self._turn * q1 + self._yaw_offset - target_yaw))
        branches = [base + k * TWO_PI for k in (-1, 0, 1)]
        lo, hi = self._wrist_lo, self._wrist_hi  # wrist_inside
        return q1, [b for b in branches if lo < b < hi] or branches

    def _subgoal_yaw(
        self, q_first: float, q_last_now: float, target_yaw: float, aim: tuple[float, list[float]]
    ) -> float:
        """:meth:`yaw_subgoal`'s yaw at the kinematics last set, the joints' first and last
        at ``q_first``, ``q_last_now``; sets the branch the posture pull takes."""
        yaw = yaw_of(self._site_xmat)
        q1, branches = aim
        d = wrap(target_yaw - yaw)
        q_last, off = branches[0], abs(branches[0] - q_last_now)
        for b in branches[1:]:  # the first nearest, as min(key=) would
            if abs(b - q_last_now) < off:
                q_last, off = b, abs(b - q_last_now)
        self._q_last_goal = min(max(q_last, self._last_lo), self._last_hi)
        turn, roll = self._turn, self._roll
        # The unwrapped yaw change on that branch.
        planned = (turn * q1 - roll * q_last) - (turn * q_first - roll * q_last_now)
        d += TWO_PI * round((planned - d) / TWO_PI)
        return yaw + min(max(d, -0.5), 0.5)

    def wrist_inside(self, q_last: float) -> bool:
        """Whether the last joint at ``q_last`` [rad] is :data:`WRIST_MARGIN` inside its limits."""
        return self._wrist_lo < q_last < self._wrist_hi

    def wrist_short_way(self, target: np.ndarray, q_last_now: float) -> float:
        """The last joint's angle [rad] that points the gripper down at ``target``'s yaw
        (``[x, y, z, yaw]``) in the home posture's shape, on the branch nearest
        ``q_last_now``: where the wrist turns the short way. If it is not
        :meth:`wrist_inside` the limits, :meth:`yaw_subgoal` turns the hand the long way
        round instead, nearly a full turn with whatever it holds (what a goal yaw equivalent
        by the gripper's symmetry avoids, :func:`~smccli.learn.frames.goal_from_object`)."""
        x, y, z, target_yaw = np.asarray(target, dtype=float).tolist()
        q1 = self.frame.bearing(x, y, z)
        base = wrap(self._roll * (self._turn * q1 + self._yaw_offset - target_yaw))
        return base + 2 * math.pi * round((q_last_now - base) / (2 * math.pi))

    def update(self, target: np.ndarray) -> np.ndarray:
        """Joint targets for this control tick, shape (n,) [rad]; joint speed is capped.

        Up to ``iterations`` IK steps: the first always (the posture pull acts every tick),
        the others while the POI is not within :data:`TRACKED` of the target. Each is
        :meth:`_ik_step` towards :meth:`yaw_subgoal`, the target's own parts computed once."""
        target = np.asarray(target, dtype=float)
        x, y, z, target_yaw = target.tolist()
        position = target[:3]
        aim = self._aim(x, y, z, target_yaw)
        q = self.q
        # The last tick's final check left the kinematics at this q, most ticks.
        placed = q if q.tobytes() == self._placed else None
        budget = self.max_step
        tol_pos, tol_rot = TRACKED[0] ** 2, TRACKED[1] ** 2
        e, e_pos, e_rot = self._e, self._e_pos, self._e_rot
        for i in range(self.iterations):
            if placed is not q:
                self._place(q)
                placed = q
            q_list = q.tolist()
            yaw = self._subgoal_yaw(q_list[0], q_list[-1], target_yaw, aim)
            np.subtract(position, self._site_xpos, out=e_pos)
            self._rotation_error(yaw)
            if i and e_pos.dot(e_pos) < tol_pos and e_rot.dot(e_rot) < tol_rot:
                break
            mujoco.mj_comPos(self.model, self.data)
            q_new = self._advance(q, q_list, aim[0], budget, e)
            budget -= max(map(abs, map(operator.sub, q_new.tolist(), q_list)))
            q = q_new
            if budget <= 1e-9:
                break
        self._placed = b"" if placed is None else placed.tobytes()
        self.q = q
        return q

    def solve(
        self,
        target: np.ndarray,
        q0: np.ndarray | None = None,
        *,
        max_iterations: int = 300,
        tol_pos: float = 1e-3,
        tol_rot: float = math.radians(0.5),
    ) -> tuple[np.ndarray, bool]:
        """Full IK from ``q0`` (default home): joint positions and whether they converged."""
        target = np.asarray(target, dtype=float)
        q = self.home.copy() if q0 is None else np.asarray(q0, dtype=float).copy()
        # Start the base yaw pointing at the target: avoids the DLS wandering at the start.
        q[0] = np.clip(self.frame.bearing(*target[:3].tolist()), self.lo[0], self.hi[0])
        for _ in range(max_iterations):
            self._set(q)
            e = self._error(target)
            if np.linalg.norm(e[:3]) < tol_pos and np.linalg.norm(e[3:]) < tol_rot:
                return q, True
            q = self._ik_step(q, self._yaw_subgoal(q, target), 0.2)
        e = self.error(q, target)
        return q, bool(np.linalg.norm(e[:3]) < tol_pos and np.linalg.norm(e[3:]) < tol_rot)


def reach_problem(
    model: mujoco.MjModel, robot: Robot, target: np.ndarray, *, min_z: float = 0.01
) -> str | None:
    """Why the POI cannot reach ``target`` [x, y, z, yaw] pointing down, or None when the
    IK converges; a mobile base without an arm reaches any finite pose (walls stop it, not
    its joints).

    The reason says what fails: the position (by how much) or only the orientation, and
    which joints the IK left at a limit. ``min_z`` [m]: lowest POI height above the table
    accepted (keeps the fingertips out).
    """
    target = np.asarray(target, dtype=float)
    if target.shape != (4,) or not np.all(np.isfinite(target)):
        return "not a finite [x, y, z, yaw]"
    if not robot.arm_joints:  # a mobile base: its joints take the pose as it is
        return None
    if target[2] < min_z:
        return f"below the lowest POI height ({min_z} m above the table)"
    controller = CartesianController(model, robot)
    q, ok = controller.solve(target)
    if ok:
        return None
    e = controller.error(q, target)
    pos, rot = float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:]))
    at = [
        f"{name} at its {'lower' if qi <= lo + 1e-3 else 'upper'} limit {qi:.2f} rad"
        for name, qi, lo, hi in zip(robot.arm_joints, q, controller.lo, controller.hi, strict=True)
        if qi <= lo + 1e-3 or qi >= hi - 1e-3
    ]
    if pos >= 1e-3:
        what = f"the position stays {pos * 1000:.0f} mm short"
    else:
        what = f"the position is reached but the gripper stays {math.degrees(rot):.0f} deg off"
    return what + (f" ({', '.join(at)})" if at else "")


def reachable(
    model: mujoco.MjModel, robot: Robot, target: np.ndarray, *, min_z: float = 0.01
) -> bool:
    """Whether :func:`reach_problem` finds none."""
    return reach_problem(model, robot, target, min_z=min_z) is None


def home_poi(model: mujoco.MjModel, robot: Robot) -> np.ndarray:
    """The POI ``[x, y, z, yaw]`` at the robot's home posture, in the model's frame (a
    mobile manipulator's base frame: its base joints at zero)."""
    return CartesianController(model, robot).forward(robot.home_array())
