"""What the robot gives the policy at a decision point (:class:`Observation`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from smccli.errors import SmcError
from smccli.perception.scan import Scan2D
from smccli.world.sensors import CameraFrame, RobotGeometry


@dataclass(frozen=True, eq=False)
class Observation:
    """What the robot perceives at a decision point, once its last action has settled.

    Every pose is in one fixed frame, the "world" the demonstrations were recorded in (for
    an arm: the frame of its POI commands; for a mobile base: odometry's frame). Only what
    the current node's SMCs were taught with is needed;
    :meth:`~smccli.execute.policy.TreePolicy.decide` names what is missing (SmcError).
    """

    t: float
    """Time of the readings [s] (any clock; it only stamps the decision)."""
    poi: np.ndarray
    """The POI now ``[x, y, z, yaw]`` [m, m, m, rad]: an arm's end-effector site, gripper
    pointing down; a mobile base's odometry pose (z = 0). The plan starts here."""
    camera: CameraFrame | None = None
    """The RGB-D frame (:class:`~smccli.world.sensors.CameraFrame`: rgb (H, W, 3) uint8,
    depth (H, W) [m] along the optical axis (0 where unknown), K (3, 3) [px],
    T_world_camera (4, 4) in the optical convention x right, y down, z forward). Needed
    by an arm's SMCs with an object and a base's with the room's colours."""
    robot_geometry: RobotGeometry | None = None
    """The robot's own links as spheres in the world frame, to remove them from the cloud
    (self-filter), e.g. ``RobotModel.from_mjcf(scene.mjcf, robot.joint_names)
    .geometry_for(joint_positions)`` (:mod:`smccli.world.robot_model`; positions in the
    order of ``robot.joint_names``). None: nothing is filtered (only safe when the robot is
    out of the camera's view)."""
    weight: float | None = None
    """The scale's reading at the decision point [kg], tared: the median of the last
    ``tree.params.weight_window`` seconds of readings
    (:func:`smccli.perception.scale_reading`). Needed by SMCs taught with a scale."""
    scan: Scan2D | None = None
    """A mobile base's lidar scan in the lidar's own frame. Needed by SMCs with a scan."""
    lidar_pose: np.ndarray | None = None
    """The lidar's pose ``[x, y, yaw]`` in odometry's frame when the scan was taken
    [m, m, rad]. Needed with ``scan``: it maps a goal stored relative to the taught scan."""
    joints: np.ndarray | None = None
    """An arm's joint readings in ``robot.arm_joints`` order, shape (n,) [rad]: which way
    its wrist turns to a goal (:meth:`~smccli.execute.policy.TreePolicy.map_goal`). None:
    as the POI's yaw says."""
    base: np.ndarray | None = None
    """A mobile manipulator's base pose ``[x, y, yaw]`` from odometry [m, m, rad]; its
    ``poi`` is then the hand in odometry's frame (this pose composed with the hand in the
    base's frame, :func:`smccli.world.geometry.compose`)."""

    def __post_init__(self) -> None:
        self._vector("poi", "[x, y, z, yaw]")
        if self.lidar_pose is not None:
            self._vector("lidar_pose", "[x, y, yaw]")
        if self.base is not None:
            self._vector("base", "[x, y, yaw]")

    def _vector(self, name: str, form: str) -> None:
        """Store field ``name`` as float64, or SmcError unless it holds ``form``'s finite
        numbers."""
        raw = getattr(self, name)
        v = np.asarray(raw, dtype=np.float64)
        n = form.count(",") + 1
        if v.shape != (n,) or not np.all(np.isfinite(v)):
            raise SmcError(
                f"observation at t={self.t:.3f} s: {name} must be {n} finite numbers "
                f"{form}, got {np.asarray(raw).tolist()}"
            )
        object.__setattr__(self, name, v)
