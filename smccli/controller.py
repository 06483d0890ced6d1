"""Cartesian controller: a POI target ``[x, y, z, yaw]`` (gripper pointing down) to joint targets.

Damped least squares on ``mj_jacSite`` (position and orientation), with a nullspace pull
towards a comfortable posture:

    dq = Jᵀ (J Jᵀ + λ² I)⁻¹ e  +  (I − J⁺ J) k (q_home − q)

where ``e`` stacks the position error [m] and the orientation error (axis-angle, world
frame) [rad]. The controller solves on its own ``MjData`` (kinematics only) from the last
joint target, so the position servos receive a consistent, smooth target and the robot's
dynamics (sag, contacts) never feed back into the IK. The same controller serves teleop
and replay.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from smccli.errors import SceneError

ARM_JOINTS = tuple(f"joint{i}" for i in range(1, 8))
ARM_ACTUATORS = tuple(f"act{i}" for i in range(1, 8))
GRIPPER_JOINTS = ("finger_left_joint", "finger_right_joint")
GRIPPER_ACTUATOR = "gripper"
POI_SITE = "poi"
HOME = np.array([0.0, 0.2, 0.0, 1.9, 0.0, 1.04, 0.0])
"""Comfortable posture [rad], elbow up, gripper down; the nullspace pulls towards it."""

# Flip so that the POI z axis points down; the yaw then rotates about world z.
_DOWN = np.diag([1.0, -1.0, -1.0])


def target_rotation(yaw: float) -> np.ndarray:
    """POI orientation for a gripper pointing down at ``yaw`` [rad], shape (3, 3)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ _DOWN


def wrap(angle: float) -> float:
    """Angle wrapped to (−π, π] [rad]."""
    return math.pi - (math.pi - angle) % (2 * math.pi)


def rotation_error(R_target: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Axis-angle vector of ``R_target Rᵀ`` (world frame), shape (3,) [rad]."""
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, (R_target @ R.T).ravel())
    err = np.empty(3)
    mujoco.mju_quat2Vel(err, quat, 1.0)
    return err


def poi_pose(data: mujoco.MjData, site_id: int) -> np.ndarray:
    """POI ``[x, y, z, yaw]`` from a site's pose; yaw is that of the site's x axis."""
    R = data.site_xmat[site_id].reshape(3, 3)
    return np.array([*data.site_xpos[site_id], math.atan2(R[1, 0], R[0, 0])])


class CartesianController:
    """Turns POI targets into arm joint targets, one control tick at a time."""

    def __init__(
        self,
        model: mujoco.MjModel,
        *,
        site: str = POI_SITE,
        damping: float = 0.03,
        nullspace_gain: float = 0.2,
        max_joint_speed: float = 2.5,
        control_period: float = 0.01,
        iterations: int = 3,
    ) -> None:
        self.model = model
        self.data = mujoco.MjData(model)  # scratch: kinematics for the IK only
        self.site_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, site)
        if self.site_id < 0:
            raise SceneError(f"model has no POI site {site!r}")
        jids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in ARM_JOINTS]
        if min(jids) < 0:
            raise SceneError(f"model lacks the arm joints {', '.join(ARM_JOINTS)}")
        self.qadr = np.array([model.jnt_qposadr[j] for j in jids])
        self.dofadr = np.array([model.jnt_dofadr[j] for j in jids])
        self.lo = model.jnt_range[jids, 0].copy()
        self.hi = model.jnt_range[jids, 1].copy()
        self.damping = damping
        self.nullspace_gain = nullspace_gain
        self.max_step = max_joint_speed * control_period
        self.iterations = iterations
        self.q = HOME.copy()
        """Current joint target, shape (7,) [rad]."""
        self._jacp = np.zeros((3, model.nv))
        self._jacr = np.zeros((3, model.nv))

    def reset(self, q: np.ndarray) -> None:
        """Restart from joint positions ``q``, shape (7,) [rad]."""
        self.q = np.clip(np.asarray(q, dtype=float), self.lo, self.hi)

    def forward(self, q: np.ndarray) -> np.ndarray:
        """POI ``[x, y, z, yaw]`` at joint positions ``q`` (forward kinematics)."""
        self._set(q)
        return poi_pose(self.data, self.site_id)

    def _set(self, q: np.ndarray) -> None:
        self.data.qpos[self.qadr] = q
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_comPos(self.model, self.data)

    def error(self, q: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Task error at ``q``: position [m] and orientation [rad], shape (6,)."""
        self._set(q)
        pos = self.data.site_xpos[self.site_id]
        R = self.data.site_xmat[self.site_id].reshape(3, 3)
        return np.concatenate([target[:3] - pos, rotation_error(target_rotation(target[3]), R)])

    def ik_step(self, q: np.ndarray, target: np.ndarray, max_step: float | None) -> np.ndarray:
        """One damped-least-squares step from ``q`` towards ``target``; returns the new q."""
        e = self.error(q, target)
        mujoco.mj_jacSite(self.model, self.data, self._jacp, self._jacr, self.site_id)
        J = np.vstack([self._jacp[:, self.dofadr], self._jacr[:, self.dofadr]])
        JJt = J @ J.T + self.damping**2 * np.eye(6)
        dq = J.T @ np.linalg.solve(JJt, e)
        # Nullspace: keep the elbow and the redundant rolls near the home posture.
        # Exact projector (not the damped one), so the posture pull leaves no task error.
        N = np.eye(7) - np.linalg.pinv(J, rcond=1e-4) @ J
        posture = HOME - q
        # The base yaw's comfortable value points the arm at the target.
        posture[0] = wrap(math.atan2(target[1], target[0]) - q[0])
        dq += N @ (self.nullspace_gain * posture)
        if max_step is not None:
            biggest = np.max(np.abs(dq))
            if biggest > max_step:
                dq *= max_step / biggest
        return np.clip(q + dq, self.lo, self.hi)

    def yaw_subgoal(self, q: np.ndarray, target: np.ndarray) -> np.ndarray:
        """``target`` with its yaw replaced by a waypoint at most 0.5 rad from the current yaw.

        The orientation error alone always turns the short way, which can drive the wrist
        roll into its limit. Pointing down, yaw ≈ q1 − q7; with q1 settling at the target's
        bearing, pick the q7 branch inside the limits closest to the current q7 and turn
        the way that leads there.
        """
        self._set(q)
        R = self.data.site_xmat[self.site_id].reshape(3, 3)
        yaw = math.atan2(R[1, 0], R[0, 0])
        d = wrap(target[3] - yaw)
        q1 = math.atan2(target[1], target[0])
        base = wrap(q1 - target[3])
        branches = [base + k * 2 * math.pi for k in (-1, 0, 1)]
        inside = [b for b in branches if self.lo[6] + 0.05 < b < self.hi[6] - 0.05]
        q7 = min(inside or branches, key=lambda b: abs(b - q[6]))
        planned = (q1 - q7) - (q[0] - q[6])  # unwrapped yaw change on that branch
        d += 2 * math.pi * round((planned - d) / (2 * math.pi))
        sub = np.array(target, dtype=float)
        sub[3] = yaw + float(np.clip(d, -0.5, 0.5))
        return sub

    def update(self, target: np.ndarray) -> np.ndarray:
        """Joint targets for this control tick, shape (7,) [rad]; joint speed is capped."""
        target = np.asarray(target, dtype=float)
        q = self.q
        budget = self.max_step
        for _ in range(self.iterations):
            q_new = self.ik_step(q, self.yaw_subgoal(q, target), budget)
            budget -= float(np.max(np.abs(q_new - q)))
            q = q_new
            if budget <= 1e-9:
                break
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
        q = HOME.copy() if q0 is None else np.asarray(q0, dtype=float).copy()
        # Start the base yaw pointing at the target: avoids the DLS wandering at the start.
        q[0] = np.clip(math.atan2(target[1], target[0]), self.lo[0], self.hi[0])
        for _ in range(max_iterations):
            e = self.error(q, target)
            if np.linalg.norm(e[:3]) < tol_pos and np.linalg.norm(e[3:]) < tol_rot:
                return q, True
            q = self.ik_step(q, self.yaw_subgoal(q, target), 0.2)
        e = self.error(q, target)
        return q, bool(np.linalg.norm(e[:3]) < tol_pos and np.linalg.norm(e[3:]) < tol_rot)


def reachable(model: mujoco.MjModel, target: np.ndarray, *, min_z: float = 0.01) -> bool:
    """Whether the POI can reach ``target`` [x, y, z, yaw] pointing down (IK converges).

    ``min_z`` [m] keeps the fingertips out of the table (the POI sits 1.5 cm above them).
    """
    target = np.asarray(target, dtype=float)
    if target.shape != (4,) or not np.all(np.isfinite(target)) or target[2] < min_z:
        return False
    _, ok = CartesianController(model).solve(target)
    return ok
