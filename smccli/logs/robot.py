"""The robot's own body in a log: a kinematic copy posed from the logged joint readings.

The self-filter of compile and inspect (:mod:`smccli.world.robot_model`) applied to what a
log holds: the scene MJCF it attaches and its ``/robot/joint_states``.
"""

from __future__ import annotations

import mujoco
import numpy as np

from smccli.errors import LogError
from smccli.logs.log import Log
from smccli.world.compiled import compile_mjcf
from smccli.world.robot_model import RobotModel, robot_body_ids
from smccli.world.scene import ASSET_PREFIX
from smccli.world.sensors import RobotGeometry


def robot_model_of(log: Log) -> RobotModel:
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
        assets = {
            name.removeprefix(ASSET_PREFIX): bytes(data)
            for name, data in log.attachments.items()
            if name.startswith(ASSET_PREFIX)
        }  # the files the MJCF names (a vendor robot's meshes)
        model = compile_mjcf(text, assets)
    except ValueError as exc:  # MuJoCo's parse and compile errors
        raise LogError(f"{where}: MuJoCo rejects the MJCF ({' '.join(str(exc).split())})") from None
    names = tuple(log.joint_states[0].names) if log.joint_states else ()
    unknown = [n for n in names if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) < 0]
    if unknown:
        have = [model.joint(i).name for i in range(model.njnt)]
        shown = ", ".join(have[:12]) + (", ..." if len(have) > 12 else "")
        raise LogError(
            f"{where}: no joint {unknown[0]!r} (named by /robot/joint_states; "
            f"the MJCF has {shown or 'no joints'})"
        )
    return RobotModel(model, mujoco.MjData(model), names, robot_body_ids(model, names))


def geometry_at(robot: RobotModel, log: Log, t: float) -> RobotGeometry:
    """Robot spheres at the logged joint state nearest ``t`` (self-filter of a logged frame)."""
    times = np.array([js.t for js in log.joint_states])
    js = log.joint_states[int(np.argmin(np.abs(times - t)))]
    return robot.geometry_for(js.position)
