"""What control may use during replay: the robot's sensors and its command input.

Honesty (docs/design.md section 2): the executor (:mod:`smccli.execute.executor`) sees the
simulator only through :class:`Sensors`, which has no ground truth and no object state:
sensor readings, joint encoders and the scene's nominal model. Object poses are read after
control by :mod:`smccli.execute.evaluation`. ``tests/test_honesty.py`` audits every access
to the simulator during control, on an arm, a base and a mobile manipulator.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from smccli.errors import SmcError
from smccli.perception.scan import Scan2D
from smccli.world.sensors import CameraFrame, JointState, PoiCommand, RobotGeometry

if TYPE_CHECKING:  # the type only: control holds a Sim through this facade alone
    from smccli.world.sim import Sim


class Sensors:
    """What control may use: the robot's sensors and its command input, nothing else.

    A facade over :class:`Sim` without ground truth or object state; ``on_step`` (the
    replay log) observes each control period.
    """

    def __init__(self, sim: Sim, on_step: Callable[[PoiCommand], None] | None = None) -> None:
        self._sim = sim
        self._on_step = on_step
        self.model = sim.scene.model()
        """The scene compiled afresh from its files: the robot and the scene where the
        scene file puts them (for reachability). Not the simulator's model, which each
        layout rewrites (bins, scale, wardrobe, tables): control never sees where a layout
        put anything."""
        self.robot = sim.robot
        """The robot file: joints, POI, gripper, home posture."""
        self.control_period = sim.control_period
        """Control period [s]."""
        self.has_scale = sim.scene.scale is not None
        """The scene has a scale under the table."""
        self.has_lidar = sim.lidar_pose() is not None
        """The robot has a 2-D lidar."""
        self.camera_windows = sim.camera_windows
        """:meth:`render_camera` of a region draws that region alone (a camera without a
        noise model); a noisy camera's every frame costs a whole frame's depth and noise,
        and a frame more changes the noise of every later one."""
        self.mobile_manipulator = sim.mobile_manipulator
        """A base and an arm: :meth:`poi` is the hand in the base's frame, :meth:`base` the
        base's pose."""

    @property
    def t(self) -> float:
        """Simulation time [s]."""
        return self._sim.t

    def step(self, cmd: PoiCommand) -> None:
        """Send one command and advance one control period."""
        self._sim.step(cmd)
        if self._on_step is not None:
            self._on_step(cmd)

    def poi(self) -> np.ndarray:
        """POI ``[x, y, z, yaw]`` [m, m, m, rad] (a mobile manipulator's: in its base's frame)."""
        return self._sim.poi()

    def base(self) -> np.ndarray:
        """A mobile base's pose ``[x, y, yaw]`` from odometry [m, m, rad]."""
        return self._sim.base_odometry()

    def gripper_opening(self) -> float:
        """Finger opening over its maximum, in [0, 1]."""
        return self._sim.gripper_opening()

    def gripper_speed(self) -> float:
        """Rate of change of the opening [1/s]."""
        return self._sim.gripper_speed()

    def joint_state(self) -> JointState:
        return self._sim.joint_state()

    def weight(self) -> float | None:
        """Scale reading [kg]; None without a scale."""
        return self._sim.weight()

    def lidar(self) -> Scan2D:
        """A scan of the robot's lidar, in its own frame (:attr:`has_lidar`). The simulator's
        reading also carries the true pose; control gets :meth:`lidar_pose` instead."""
        r = self._sim.lidar()
        if r is None:
            raise SmcError(f"robot {self.robot.name!r} has no lidar")
        return Scan2D(r.ranges, r.angle_min, r.angle_increment, r.range_max)

    def lidar_pose(self) -> np.ndarray:
        """The lidar's pose ``[x, y, yaw]`` from odometry and its mounting [m, m, rad]."""
        pose = self._sim.lidar_pose()
        if pose is None:
            raise SmcError(f"robot {self.robot.name!r} has no lidar")
        return pose

    def render_camera(
        self,
        region: tuple[int, int, int, int] | None = None,
        colour: bool = True,
        *,
        colour_later: bool = False,
    ) -> CameraFrame:
        """An RGB-D frame; with ``region`` ``(v0, v1, u0, u1)`` only those rows and columns
        are read (elsewhere no reading), without ``colour`` the depth alone, with
        ``colour_later`` the colours read at their first use (a decision perceives the
        depth while they are drawn): :meth:`Sim.render_camera`."""
        return self._sim.render_camera(region, colour, colour_later=colour_later)

    def camera_view(self) -> tuple[np.ndarray, np.ndarray, tuple[int, int], float]:
        """The camera's intrinsics K (3, 3) [px], pose T_world_camera (4, 4, optical frame),
        image shape (h, w) and near clipping distance [m]: where a frame's pixels look,
        before rendering it."""
        cam = self._sim.scene.camera
        return (
            self._sim.camera_matrix(),
            self._sim.camera_pose(),
            (cam.height, cam.width),
            self._sim.camera_near(),
        )

    def camera_near(self) -> float:
        """The camera's near clipping distance [m]: no depth reading is nearer."""
        return self._sim.camera_near()

    def robot_geometry(self) -> RobotGeometry:
        """The robot's own links from its kinematic model and joint readings (self-filter)."""
        return self._sim.robot_geometry()
