"""The robot's own body, from its kinematic model and joint readings (for the self-filter).

Removing the robot's points from a point cloud with its known geometry is allowed by the
honesty rule: it uses the robot's model and its joint encoders, never simulator knowledge
of the objects. Each robot geom is covered by a few spheres (a capsule by spheres along its
axis, a box along its longest side) inflated by a margin.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import mujoco
import numpy as np

from smccli.world.compiled import compile_mjcf
from smccli.world.sensors import RobotGeometry

MARGIN = 0.012
"""Inflation of every sphere [m]: covers depth noise at the robot's surface."""


def subtree_bodies(model: mujoco.MjModel, roots: Iterable[int]) -> set[int]:
    """The bodies ``roots`` (ids) and all their descendants."""
    roots = set(roots)
    ids: set[int] = set()
    for b in range(model.nbody):
        a = b
        while a > 0:
            if a in roots:
                ids.add(b)
                break
            a = int(model.body_parentid[a])
    return ids


def robot_body_ids(model: mujoco.MjModel, joint_names: tuple[str, ...]) -> np.ndarray:
    """The robot's bodies: those the named joints move (with their descendants) and the
    fixed ones they hang from, up to the robot's root (a pedestal, a mounting plate).

    The fixed ones count only when their geoms are in the groups the moving links' geoms
    use (a robot file's ``geom_group``, or a vendor's visual and collision groups): a scene
    may hang the robot from a body of its own, a table or a cart, which is not the robot.
    Without the pedestal the camera saw the robot's base as an object wherever the crop
    box reached it.
    """
    roots = {int(model.jnt_bodyid[model.joint(n).id]) for n in joint_names}
    ids = subtree_bodies(model, roots)
    moving = [g for g in range(model.ngeom) if int(model.geom_bodyid[g]) in ids]
    if moving:
        groups = set(model.geom_group[moving].tolist())
        for root in roots:
            a = int(model.body_parentid[root])
            while a > 0:
                geoms = range(model.body_geomadr[a], model.body_geomadr[a] + model.body_geomnum[a])
                if all(int(model.geom_group[g]) in groups for g in geoms):
                    ids.add(a)
                a = int(model.body_parentid[a])
    return np.array(sorted(ids), dtype=int)


def geometry(
    model: mujoco.MjModel, data: mujoco.MjData, bodies: np.ndarray, margin: float = MARGIN
) -> RobotGeometry:
    """Bounding spheres of the geoms of ``bodies`` at ``data``'s kinematics (world frame)."""
    centers: list[np.ndarray] = []
    radii: list[float] = []
    body_set = set(int(b) for b in bodies)
    for g in range(model.ngeom):
        if int(model.geom_bodyid[g]) not in body_set:
            continue
        pos = data.geom_xpos[g]
        rot = data.geom_xmat[g].reshape(3, 3)
        size = model.geom_size[g]
        gtype = int(model.geom_type[g])
        if gtype in (mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_CYLINDER):
            r, half = float(size[0]), float(size[1])
            axis, radius = rot[:, 2], r
        elif gtype == mujoco.mjtGeom.mjGEOM_BOX:
            k = int(np.argmax(size))
            half = float(size[k])
            others = np.delete(size, k)
            axis, radius = rot[:, k], float(np.linalg.norm(others))
        else:
            axis, half, radius = rot[:, 2], 0.0, float(model.geom_rbound[g])
        n = max(1, int(np.ceil(2 * half / max(radius, 1e-3))) + 1)
        for s in np.linspace(-half, half, n) if n > 1 else [0.0]:
            centers.append(pos + s * axis)
            radii.append(radius + margin)
    if not centers:
        return RobotGeometry()
    return RobotGeometry(centers=np.array(centers), radii=np.array(radii))


@dataclass
class RobotModel:
    """A kinematic copy of the robot, posed from logged joint readings."""

    model: mujoco.MjModel
    data: mujoco.MjData
    joint_names: tuple[str, ...]
    bodies: np.ndarray

    @classmethod
    def from_mjcf(
        cls,
        mjcf_xml: str,
        joint_names: tuple[str, ...],
        assets: dict[str, bytes] | None = None,
    ) -> RobotModel:
        """Build from a self-contained MJCF (as attached to every log) and the files it
        names (``Scene.assets``; a vendor robot's meshes)."""
        model = compile_mjcf(mjcf_xml, assets)
        return cls(model, mujoco.MjData(model), joint_names, robot_body_ids(model, joint_names))

    def geometry_for(self, positions: np.ndarray) -> RobotGeometry:
        """Robot spheres with the joints at ``positions`` (shape (n,), order of joint_names)."""
        for name, q in zip(self.joint_names, positions, strict=True):
            self.data.qpos[self.model.jnt_qposadr[self.model.joint(name).id]] = q
        mujoco.mj_kinematics(self.model, self.data)
        return geometry(self.model, self.data, self.bodies)
