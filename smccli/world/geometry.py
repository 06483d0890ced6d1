"""Angles, rotations and poses: the one place smc composes, inverts and compares them.

Conventions, at every module and every boundary:

* **Angles** are radians; :func:`wrap` is the one wrap, into (-period/2, period/2]
  ((-pi, pi] by default, atan2's range).
* **Quaternions** are ``[w, x, y, z]``, MuJoCo's order, everywhere inside smc. scipy, Rerun
  and ROS messages put w last: convert at that boundary only, with :func:`xyzw` and
  :func:`wxyz`.
* **Planar poses** are arrays ``[x, y, yaw]`` (..., 3) [m, m, rad], SE(2) (a base, a
  lidar, an object's footprint). A **POI** ``[x, y, z, yaw]`` (..., 4) is a planar pose
  with a height that rides along: every planar function takes either, and a frame of
  shape (4,) moves heights as well. Yaws are not wrapped by composition: a caller that
  wants (-pi, pi] wraps; a path's yaw stays continuous.
* **Spatial poses** are homogeneous transforms (4, 4); ``T_a_b`` maps points of frame b
  into frame a, and ``compose(a, b)`` is ``a * b``: b given in a's frame, into a's parent.

Poses are plain arrays, not objects, because the hot code works on many at once: a
rolled-out DMP is (n, 4), a lidar scan's poses (n, 3), MuJoCo hands over views of its own
arrays, and the control loop runs at 100 Hz. Every planar function here is vectorised
over leading axes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

TWO_PI = 2 * math.pi

# --- angles --------------------------------------------------------------------------------


def wrap(angle: float, period: float = TWO_PI) -> float:
    """``angle`` wrapped into (-period/2, period/2] [rad]; ``period`` pi wraps an axis
    (a direction defined modulo pi).

    ``(angle + period/2) % period - period/2``: the sum rounds, so an angle in range may
    move by up to half an ulp of the period (4.4e-16 rad for 2 pi). This form keeps
    compiled trees' bits (``math.remainder`` would be exact; docs/choices.md, "One
    geometry")."""
    half = period / 2
    r = (angle + half) % period - half
    return half if r == -half else r


def near(angle: float, ref: float, period: float = TWO_PI) -> float:
    """``angle`` moved by a multiple of ``period`` to within half a period of ``ref`` [rad]:
    the turn from ``ref`` the short way (a wrist's, a base's)."""
    return ref + wrap(angle - ref, period)


def wrap_yaw(poses: ArrayLike) -> np.ndarray:
    """A copy of poses (..., 3) or (..., 4) with each yaw (the last column) wrapped into
    (-pi, pi]."""
    p = np.array(poses, dtype=np.float64)
    yaws = p[..., -1].reshape(-1)
    p[..., -1] = np.array([wrap(float(a)) for a in yaws]).reshape(p.shape[:-1])
    return p


def yaw_of(R: ArrayLike) -> float:
    """Yaw [rad] of a rotation matrix (3, 3), or of its rows flattened (9,) as MuJoCo's
    ``xmat``: the heading of its x axis in the x-y plane, in [-pi, pi] (atan2)."""
    m = np.asarray(R)
    if m.ndim == 1:
        return math.atan2(m[3], m[0])
    return math.atan2(m[1, 0], m[0, 0])


# --- quaternions [w, x, y, z] -------------------------------------------------------------
# MuJoCo's mju_* conversions use our order natively and cost about 1 us a call; mujoco is
# imported on first use (its import takes about 200 ms) so that reading a log does not load it.


def yaw_quat(yaw: ArrayLike) -> np.ndarray:
    """Rotations about z by ``yaw`` (...,) [rad] as quaternions (..., 4) ``[w, x, y, z]``."""
    half = 0.5 * np.asarray(yaw, dtype=np.float64)
    q = np.zeros((*half.shape, 4))
    q[..., 0], q[..., 3] = np.cos(half), np.sin(half)
    return q


def quat_matrix(q: ArrayLike) -> np.ndarray:
    """Quaternion (4,) ``[w, x, y, z]`` of any non-zero norm -> rotation matrix (3, 3)."""
    import mujoco

    qa = np.asarray(q, dtype=np.float64)
    m = np.empty(9)
    mujoco.mju_quat2Mat(m, qa / np.linalg.norm(qa))
    return m.reshape(3, 3)


def matrix_quat(R: ArrayLike) -> np.ndarray:
    """Rotation matrix (3, 3) -> unit quaternion (4,) ``[w, x, y, z]`` with w >= 0."""
    import mujoco

    q = np.empty(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, dtype=np.float64).reshape(9))
    return -q if q[0] < 0 else q


def quat_yaw(q: ArrayLike) -> float:
    """Yaw [rad] of a quaternion ``[w, x, y, z]``: the heading of the rotated x axis."""
    return yaw_of(quat_matrix(q))


def xyzw(q: ArrayLike) -> np.ndarray:
    """Quaternions (..., 4) ``[w, x, y, z]`` -> ``[x, y, z, w]`` (scipy, Rerun, ROS)."""
    return np.asarray(q, dtype=np.float64)[..., [1, 2, 3, 0]]


def wxyz(q: ArrayLike) -> np.ndarray:
    """Quaternions (..., 4) ``[x, y, z, w]`` (scipy, Rerun, ROS) -> ``[w, x, y, z]``."""
    return np.asarray(q, dtype=np.float64)[..., [3, 0, 1, 2]]


def rotate_z(v: ArrayLike, angle: float) -> np.ndarray:
    """Points or vectors (..., 3) turned by ``angle`` [rad] about z (scipy's rotation)."""
    return Rotation.from_euler("z", angle).apply(np.asarray(v, dtype=np.float64))


# --- planar poses [x, y, yaw] and POIs [x, y, z, yaw] ------------------------------------


def compose(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """``a * b``: poses ``b`` given in the frame of ``a`` -> in ``a``'s parent frame.

    ``a`` (..., 3) or (..., 4), ``b`` (..., 3) or (..., 4); the result has ``b``'s shape
    (broadcast). Heights add when both have one; yaws add, unwrapped."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.ndim == 1 and b.ndim == 1:
        return _one_pose(a, b, inverse_a=False)
    c, s = np.cos(a[..., -1]), np.sin(a[..., -1])
    bx, by = b[..., 0], b[..., 1]
    out = [a[..., 0] + c * bx - s * by, a[..., 1] + s * bx + c * by]
    if b.shape[-1] == 4:
        out.append(b[..., 2] + a[..., 2] if a.shape[-1] == 4 else b[..., 2])
    out.append(a[..., -1] + b[..., -1])
    return np.stack(np.broadcast_arrays(*out), -1)


def between(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """``a^-1 * b``: poses ``b`` (in the parent frame) -> in the frame of ``a``.

    Shapes as :func:`compose`; the yaw is ``b``'s minus ``a``'s, unwrapped."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.ndim == 1 and b.ndim == 1:
        return _one_pose(a, b, inverse_a=True)
    c, s = np.cos(a[..., -1]), np.sin(a[..., -1])
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    out = [c * dx + s * dy, -s * dx + c * dy]
    if b.shape[-1] == 4:
        out.append(b[..., 2] - a[..., 2] if a.shape[-1] == 4 else b[..., 2])
    out.append(b[..., -1] - a[..., -1])
    return np.stack(np.broadcast_arrays(*out), -1)


def _one_pose(a: np.ndarray, b: np.ndarray, *, inverse_a: bool) -> np.ndarray:
    """:func:`compose` (or :func:`between` with ``inverse_a``) of one pose with one pose,
    the same operations on Python floats: the mobile base's odometry calls them every
    control period, where numpy's per-call overhead was most of a step's cost."""
    return np.array(pose_floats(a, b, inverse_a=inverse_a))


def pose_floats(
    a: np.ndarray | Sequence[float], b: np.ndarray | Sequence[float], *, inverse_a: bool = False
) -> list[float]:
    """:func:`compose` (or :func:`between` with ``inverse_a``) of one pose ``a`` (3,) or (4,)
    with one pose ``b``, as a list of Python floats: the same operations and bits as the
    arrays', for a loop that runs every control period and needs no array."""
    c, s = float(np.cos(a[-1])), float(np.sin(a[-1]))  # numpy's cos/sin, as for arrays
    ax, ay, ayaw = float(a[0]), float(a[1]), float(a[-1])
    bx, by, byaw = float(b[0]), float(b[1]), float(b[-1])
    if inverse_a:
        dx, dy = bx - ax, by - ay
        out = [c * dx + s * dy, -s * dx + c * dy]
    else:
        out = [ax + c * bx - s * by, ay + s * bx + c * by]
    if len(b) == 4:
        z = float(b[2])
        out.append((z - float(a[2]) if inverse_a else z + float(a[2])) if len(a) == 4 else z)
    out.append(byaw - ayaw if inverse_a else ayaw + byaw)
    return out


def inverse(a: ArrayLike) -> np.ndarray:
    """``a^-1`` of poses (..., 3) or (..., 4): ``compose(a, inverse(a))`` is the identity."""
    a = np.asarray(a, dtype=np.float64)
    return between(a, np.zeros(a.shape[-1]))


def to_frame(frame: ArrayLike, points: ArrayLike) -> np.ndarray:
    """Points (..., 2) or (..., 3) in the parent frame -> in ``frame`` (3,) or (4,);
    a height passes through unless the frame has one."""
    f, p = np.asarray(frame, dtype=np.float64), np.array(points, dtype=np.float64)
    c, s = math.cos(f[-1]), math.sin(f[-1])
    dx, dy = p[..., 0] - f[0], p[..., 1] - f[1]
    p[..., 0], p[..., 1] = c * dx + s * dy, -s * dx + c * dy
    if f.shape[-1] == 4 and p.shape[-1] == 3:
        p[..., 2] -= f[2]
    return p


def from_frame(frame: ArrayLike, points: ArrayLike) -> np.ndarray:
    """Points (..., 2) or (..., 3) in ``frame`` (3,) or (4,) -> in its parent frame."""
    f, p = np.asarray(frame, dtype=np.float64), np.array(points, dtype=np.float64)
    c, s = math.cos(f[-1]), math.sin(f[-1])
    x, y = p[..., 0].copy(), p[..., 1].copy()
    p[..., 0], p[..., 1] = f[0] + c * x - s * y, f[1] + s * x + c * y
    if f.shape[-1] == 4 and p.shape[-1] == 3:
        p[..., 2] += f[2]
    return p


def se2(pose: ArrayLike) -> np.ndarray:
    """A planar pose ``[x, y, yaw]`` -> its homogeneous transform (3, 3)."""
    x, y, yaw = (float(v) for v in np.asarray(pose)[[0, 1, -1]])
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def se2_pose(T: ArrayLike) -> np.ndarray:
    """A homogeneous transform (3, 3), or the planar part of a (4, 4) (a stray roll, pitch
    or height from ICP in 3-D is dropped) -> ``[x, y, yaw]``, yaw in (-pi, pi]."""
    M = np.asarray(T, dtype=np.float64)
    return np.array([M[0, -1], M[1, -1], wrap(yaw_of(M[:3, :3]))])


def planar_se3(pose: ArrayLike) -> np.ndarray:
    """A planar pose ``[x, y, yaw]`` or a POI ``[x, y, z, yaw]`` -> transform (4, 4)."""
    p = np.asarray(pose, dtype=np.float64)
    c, s = math.cos(p[-1]), math.sin(p[-1])
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = p[:2]
    if p.shape[-1] == 4:
        T[2, 3] = p[2]
    return T


def se2_se3(T: ArrayLike) -> np.ndarray:
    """A planar transform (3, 3) -> the same motion in 3-D (4, 4), heights unchanged."""
    M = np.asarray(T, dtype=np.float64)
    out = np.eye(4)
    out[:2, :2] = M[:2, :2]
    out[:2, 3] = M[:2, 2]
    return out


# --- spatial poses: transforms (4, 4) -----------------------------------------------------


def se3(position: ArrayLike, quat: ArrayLike) -> np.ndarray:
    """Position (3,) [m] and quaternion (4,) ``[w, x, y, z]`` -> transform (4, 4)."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = quat_matrix(quat), position
    return T


def se3_parts(T: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Transform (4, 4) -> position (3,) [m] and unit quaternion (4,) ``[w, x, y, z]``."""
    M = np.asarray(T, dtype=np.float64)
    return M[:3, 3].copy(), matrix_quat(M[:3, :3])


def se3_inverse(T: ArrayLike) -> np.ndarray:
    """The inverse of a rigid transform (4, 4): ``[R^T, -R^T p]`` (no general inverse)."""
    M = np.asarray(T, dtype=np.float64)
    out = np.eye(4)
    out[:3, :3] = M[:3, :3].T
    out[:3, 3] = -M[:3, :3].T @ M[:3, 3]
    return out


def se3_apply(T: ArrayLike, points: ArrayLike) -> np.ndarray:
    """Points (..., 3) in frame b -> in frame a, by ``T_a_b`` (4, 4)."""
    M = np.asarray(T, dtype=np.float64)
    return np.asarray(points, dtype=np.float64) @ M[:3, :3].T + M[:3, 3]
