"""The scene's camera as a pinhole, for what ``smc robots`` checks of a home posture
(:func:`smccli.world.robot_checks.check_home_view`): where an object's range lies in the
image and which pixels a set of spheres covers. No rendering: the robot's bounding spheres
(:func:`~smccli.world.robot_model.geometry`) projected, so the check needs no GL. And a
geom's box in a frame (:func:`geom_box`), where the checks measure the gripper's pads."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from smccli.world.specs import ObjectSpec, Scene


class PinholeView:
    """The scene's sensor camera as a pinhole (the intrinsics of
    :meth:`~smccli.world.sim.Sim.camera_matrix`), at ``data``'s kinematics."""

    def __init__(self, m: mujoco.MjModel, d: mujoco.MjData, scene: Scene) -> None:
        cam = m.camera(scene.camera.name).id
        self.w, self.h = scene.camera.width, scene.camera.height
        self.f = 0.5 * self.h / math.tan(math.radians(float(m.cam_fovy[cam])) / 2)
        self.R, self.t = d.cam_xmat[cam].reshape(3, 3).copy(), d.cam_xpos[cam].copy()
        self.vv, self.uu = np.mgrid[0 : self.h, 0 : self.w]

    def project(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (k, 2) and depths (k,) [m] of world points (k, 3); MuJoCo's camera
        looks along its -z, y up."""
        c = (p - self.t) @ self.R
        z = -c[:, 2]
        u = self.f * c[:, 0] / z + (self.w - 1) / 2
        v = -self.f * c[:, 1] / z + (self.h - 1) / 2
        return np.stack([u, v], axis=1), z

    def region(self, corners: np.ndarray) -> tuple[np.ndarray, float]:
        """The pixels (h, w) inside the convex hull of ``corners`` (k, 3) seen by the
        camera, and the farthest corner's depth [m] (empty behind the camera)."""
        uv, z = self.project(corners)
        if not (z > 0).all():
            return np.zeros((self.h, self.w), dtype=bool), 0.0
        return convex_mask(uv, self.w, self.h), float(z.max())

    def cover(self, centers: np.ndarray, radii: np.ndarray, far: float) -> np.ndarray:
        """The pixels (h, w) the spheres (centres (k, 3), radii (k,) [m]) cover, those
        nearer than ``far`` [m] (only they can hide what lies there)."""
        covered = np.zeros((self.h, self.w), dtype=bool)
        uv, z = self.project(centers) if len(centers) else (np.zeros((0, 2)), np.zeros(0))
        for (u, v), depth, r in zip(uv, z, radii, strict=True):
            if depth <= r or depth - r > far:
                continue
            pr = self.f * r / depth
            covered |= (self.uu - u) ** 2 + (self.vv - v) ** 2 <= pr * pr
        return covered


def range_corners(obj: ObjectSpec) -> np.ndarray:
    """The corners of the box where an object's middle lies over its range: its centre's
    range widened by a quarter of its smaller side (the middle half of its footprint),
    its height at the nominal pose; shape (8, 3) [m]. Seeing that much of every object is
    what the first decision needs; a ring around it, the arm's own base may hide."""
    r = min(obj.size[0], obj.size[1]) / 4
    z0, z1 = obj.pose[2] - obj.size[2] / 2, obj.pose[2] + obj.size[2] / 2
    xs = (obj.range_x[0] - r, obj.range_x[1] + r)
    ys = (obj.range_y[0] - r, obj.range_y[1] + r)
    return np.array([[x, y, z] for x in xs for y in ys for z in (z0, z1)])


def convex_mask(uv: np.ndarray, w: int, h: int) -> np.ndarray:
    """The pixels (h, w) inside the convex hull of the points ``uv`` (k, 2) [px]."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        eq = ConvexHull(uv).equations
    except QhullError:  # a degenerate (flat) range seen edge on
        return np.zeros((h, w), dtype=bool)
    vv, uu = np.mgrid[0:h, 0:w]
    pts = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(float)
    inside = (pts @ eq[:, :2].T + eq[:, 2] <= 0).all(axis=1)
    return inside.reshape(h, w)


def link_spheres(
    m: mujoco.MjModel, d: mujoco.MjData, bodies: set[int]
) -> tuple[np.ndarray, np.ndarray]:
    """Spheres covering every geom of ``bodies`` at ``data``'s kinematics, collision and
    visual alike (the camera sees both): centres (k, 3) [m] and radii (k,) [m].

    Spheres along a capsule's or a cylinder's axis, as
    :func:`~smccli.world.robot_model.geometry` places them; any other geom's bounding box
    (``geom_aabb``, in its own frame: a box's own) is covered along its longest side. That
    function's one sphere around a mesh (``geom_rbound``) is looser: measured on
    robosuite's UR5e at its home in bench_pick, its links cover 33 % of the white box's
    range with those, 25 % with these, and hide 9.5 % rendered (segmentation)."""
    centers: list[np.ndarray] = []
    radii: list[float] = []
    round_ = (int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_CYLINDER))
    for g in range(m.ngeom):
        if int(m.geom_bodyid[g]) not in bodies:
            continue
        rot = d.geom_xmat[g].reshape(3, 3)
        if int(m.geom_type[g]) in round_:
            centre, k = d.geom_xpos[g], 2
            radius, length = float(m.geom_size[g, 0]), float(m.geom_size[g, 1])
        else:
            centre = d.geom_xpos[g] + rot @ m.geom_aabb[g, :3]
            half = m.geom_aabb[g, 3:]
            k = int(np.argmax(half))
            radius, length = float(np.linalg.norm(np.delete(half, k))), float(half[k])
        n = max(1, int(np.ceil(2 * length / max(radius, 1e-3))) + 1)
        for s in np.linspace(-length, length, n) if n > 1 else [0.0]:
            centers.append(centre + s * rot[:, k])
            radii.append(radius)
    return np.array(centers).reshape(-1, 3), np.array(radii)


_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])


def geom_box(
    m: mujoco.MjModel,
    d: mujoco.MjData,
    g: int,
    frame: tuple[np.ndarray, np.ndarray],
    window: float | None = None,
) -> np.ndarray | None:
    """Geom ``g``'s bounding box in ``frame`` = (origin (3,), rotation (3, 3)) at ``d``'s
    kinematics: rows min and max, shape (2, 3) [m]. A mesh's box holds its vertices, a
    primitive's its axis-aligned box's corners. With ``window``, only the part within
    ``window`` of the frame's origin along its z (None where the geom has none)."""
    mesh = int(m.geom_dataid[g])
    is_mesh = m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH and mesh >= 0
    if is_mesh:
        adr, n = int(m.mesh_vertadr[mesh]), int(m.mesh_vertnum[mesh])
        points = m.mesh_vert[adr : adr + n]
    else:
        points = m.geom_aabb[g, :3] + m.geom_aabb[g, 3:] * _CORNERS
    world = d.geom_xpos[g] + points @ d.geom_xmat[g].reshape(3, 3).T
    local = (world - frame[0]) @ frame[1]
    if window is not None and is_mesh:
        local = local[np.abs(local[:, 2]) <= window]
        if not len(local):
            return None
    box = np.array([local.min(axis=0), local.max(axis=0)])
    if window is not None and not is_mesh:
        box[:, 2] = np.clip(box[:, 2], -window, window)
        if box[0, 2] >= box[1, 2]:
            return None
    return box
