"""The robot's own body, from its kinematic model and joint readings (for the self-filter).

Removing the robot's points from a point cloud with its known geometry is allowed by the
honesty rule: it uses the robot's model and its joint encoders, never simulator knowledge
of the objects. Each robot geom is covered by a few spheres (a capsule by spheres along its
axis, a box along its longest side) inflated by a margin.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from smccli.errors import LogError
from smccli.sensors import RobotGeometry

if TYPE_CHECKING:
    from smccli.logs import Log

MARGIN = 0.012
"""Inflation of every sphere [m]: covers depth noise at the robot's surface."""


def robot_body_ids(model: mujoco.MjModel, joint_names: tuple[str, ...]) -> np.ndarray:
    """Bodies moved by the named joints and their descendants (the robot's moving links)."""
    ids: set[int] = set()
    roots = {int(model.jnt_bodyid[model.joint(n).id]) for n in joint_names}
    for b in range(model.nbody):
        a = b
        while a > 0:
            if a in roots:
                ids.add(b)
                break
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
    def from_mjcf(cls, mjcf_xml: str, joint_names: tuple[str, ...]) -> RobotModel:
        """Build from a self-contained MJCF (as attached to every log)."""
        model = mujoco.MjModel.from_xml_string(mjcf_xml)
        return cls(model, mujoco.MjData(model), joint_names, robot_body_ids(model, joint_names))

    @classmethod
    def from_log(cls, log: Log) -> RobotModel:
        """Build from the scene MJCF attached to a log and its joint names.

        LogError naming the log and the attachment when the MJCF is missing, not text,
        rejected by MuJoCo, or lacks a joint that ``/robot/joint_states`` names.
        """
        where = f"{log.path}: attachment scene.xml"
        xml = log.attachments.get("scene.xml")
        if xml is None:
            raise LogError(f"{where} missing (the scene's MJCF)")
        try:
            text = xml.decode() if isinstance(xml, bytes) else xml
        except UnicodeDecodeError as exc:
            raise LogError(f"{where}: not UTF-8 text ({exc})") from None
        try:
            model = mujoco.MjModel.from_xml_string(text)
        except ValueError as exc:  # MuJoCo's parse and compile errors
            raise LogError(
                f"{where}: MuJoCo rejects the MJCF ({' '.join(str(exc).split())})"
            ) from None
        names = tuple(log.joint_states[0].names) if log.joint_states else ()
        unknown = [n for n in names if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) < 0]
        if unknown:
            have = [model.joint(i).name for i in range(model.njnt)]
            shown = ", ".join(have[:12]) + (", ..." if len(have) > 12 else "")
            raise LogError(
                f"{where}: no joint {unknown[0]!r} (named by /robot/joint_states; "
                f"the MJCF has {shown or 'no joints'})"
            )
        return cls(model, mujoco.MjData(model), names, robot_body_ids(model, names))

    def geometry_for(self, positions: np.ndarray) -> RobotGeometry:
        """Robot spheres with the joints at ``positions`` (shape (n,), order of joint_names)."""
        for name, q in zip(self.joint_names, positions, strict=True):
            self.data.qpos[self.model.jnt_qposadr[self.model.joint(name).id]] = q
        mujoco.mj_kinematics(self.model, self.data)
        return geometry(self.model, self.data, self.bodies)

    def geometry_at(self, log, t: float) -> RobotGeometry:
        """Robot spheres at the logged joint state nearest ``t``."""
        times = np.array([js.t for js in log.joint_states])
        js = log.joint_states[int(np.argmin(np.abs(times - t)))]
        return self.geometry_for(js.position)
