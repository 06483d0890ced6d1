"""The robot drawn from its own geometry in Rerun: the MJCF a log attaches, posed over time
by the log's joint readings (``/robot/joint_states``).

Each body of the robot is an entity ``/world/robot/<body>`` with its pose over time (a
Transform3D column, at most ``RATE`` Hz); each of its visible geoms a static child in the
body's frame: boxes, spheres and ellipsoids, capsules, cylinders and meshes, in the geom's
own colour. The robot is every body under the top-level bodies that carry a logged joint
(an arm's pedestal is drawn too, the table it stands on is not).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from smccli.errors import SmcError
from smccli.world.geometry import xyzw

if TYPE_CHECKING:
    import rerun as rr

    from smccli.logs.log import Log

RATE = 20.0
"""Poses drawn per second of log at most [Hz]."""
_VISIBLE_GROUPS = (0, 1, 2, 3)
"""MuJoCo geom groups drawn (4 and 5 are hidden by convention: collision proxies)."""


def robot_bodies(model: mujoco.MjModel, joint_names: tuple[str, ...]) -> list[int]:
    """Every body under a top-level body (child of the world) that carries a named joint."""
    tops: set[int] = set()
    for name in joint_names:
        b = int(model.jnt_bodyid[model.joint(name).id])
        while int(model.body_parentid[b]) != 0:
            b = int(model.body_parentid[b])
        tops.add(b)
    out = []
    for b in range(1, model.nbody):
        a = b
        while a != 0 and a not in tops:
            a = int(model.body_parentid[a])
        if a != 0:
            out.append(b)
    return out


def _entity(model: mujoco.MjModel, body: int) -> str:
    name = model.body(body).name or f"body{body}"
    return "/world/robot/" + re.sub(r"[^A-Za-z0-9_-]", "_", name)


def _rgba(model: mujoco.MjModel, g: int) -> np.ndarray:
    mat = int(model.geom_matid[g])
    rgba = model.mat_rgba[mat] if mat >= 0 else model.geom_rgba[g]
    return np.clip(np.round(np.asarray(rgba) * 255), 0, 255).astype(np.uint8)


def _shape(model: mujoco.MjModel, g: int) -> Any | None:
    """The geom as a Rerun archetype in its own frame, or None (planes, height fields)."""
    import rerun as rr

    size, colour, t = model.geom_size[g], [_rgba(model, g)], int(model.geom_type[g])
    G = mujoco.mjtGeom
    if t == G.mjGEOM_BOX:
        return rr.Boxes3D(half_sizes=[size], colors=colour, fill_mode="solid")
    if t == G.mjGEOM_SPHERE:
        return rr.Ellipsoids3D(half_sizes=[[size[0]] * 3], colors=colour, fill_mode="solid")
    if t == G.mjGEOM_ELLIPSOID:
        return rr.Ellipsoids3D(half_sizes=[size], colors=colour, fill_mode="solid")
    if t == G.mjGEOM_CAPSULE:
        # Rerun's capsule runs from its origin along +z; MuJoCo's is centred.
        return rr.Capsules3D(
            lengths=[2 * size[1]],
            radii=[size[0]],
            translations=[[0.0, 0.0, -size[1]]],
            colors=colour,
        )
    if t == G.mjGEOM_CYLINDER:
        return rr.Cylinders3D(
            lengths=[2 * size[1]], radii=[size[0]], colors=colour, fill_mode="solid"
        )
    if t == G.mjGEOM_MESH:
        m = int(model.geom_dataid[g])
        v0, nv = int(model.mesh_vertadr[m]), int(model.mesh_vertnum[m])
        f0, nf = int(model.mesh_faceadr[m]), int(model.mesh_facenum[m])
        return rr.Mesh3D(
            vertex_positions=model.mesh_vert[v0 : v0 + nv],
            triangle_indices=model.mesh_face[f0 : f0 + nf],
            albedo_factor=colour[0],
        )
    return None


def log_robot(
    rec: rr.RecordingStream, log: Log, warn: Callable[[str], None] = lambda m: None
) -> None:
    """Draw the robot of ``log`` under ``/world/robot`` on the ``time`` timeline."""
    import rerun as rr

    from smccli.inspect.views import TIMELINE
    from smccli.logs.robot import robot_model_of

    if not log.joint_states:
        return
    try:
        robot = robot_model_of(log)
    except SmcError as exc:
        warn(f"{Path(log.path).name}: robot not drawn ({str(exc).splitlines()[0]})")
        return
    model, data = robot.model, robot.data
    bodies = robot_bodies(model, robot.joint_names)
    for b in bodies:
        for g in range(model.ngeom):
            if int(model.geom_bodyid[g]) != b or int(model.geom_group[g]) not in _VISIBLE_GROUPS:
                continue
            if model.geom_rgba[g][3] == 0:
                continue
            shape = _shape(model, g)
            if shape is None:
                continue
            path = f"{_entity(model, b)}/geom{g}"
            local = rr.Transform3D(
                translation=model.geom_pos[g],
                quaternion=rr.Quaternion(xyzw=xyzw(model.geom_quat[g])),
            )
            rec.log(path, local, shape, static=True)
    times = np.array([js.t for js in log.joint_states])
    keep = [0]
    for k in range(1, len(times)):
        if times[k] - times[keep[-1]] >= 1.0 / RATE:
            keep.append(k)
    adr = [int(model.jnt_qposadr[model.joint(n).id]) for n in robot.joint_names]
    pos = np.zeros((len(keep), len(bodies), 3))
    quat = np.zeros((len(keep), len(bodies), 4))
    for i, k in enumerate(keep):
        data.qpos[adr] = log.joint_states[k].position
        mujoco.mj_kinematics(model, data)
        pos[i] = data.xpos[bodies]
        quat[i] = xyzw(data.xquat[bodies])
    index = [rr.TimeColumn(TIMELINE, duration=times[keep])]
    for j, b in enumerate(bodies):
        rec.send_columns(
            _entity(model, b),
            indexes=index,
            columns=rr.Transform3D.columns(translation=pos[:, j], quaternion=quat[:, j]),
        )
