"""``smc sim --ros1``: a scene in MuJoCo as a ROS robot, for ``smc run`` to drive.

Plain Python (the middleware in :mod:`smccli.ros.ros1` only moves what it returns): the
robot publishes what replay's executor reads, through the same facade
(:class:`smccli.execute.sensing.Sensors`: joints, POI, rendered camera, lidar, scale), and
executes POI targets and gripper commands with the simulator's own Cartesian controller.

Lockstep: the simulator advances one control period per command (a target and, with a
gripper, its finger command of the same stamp), as a simulator stepped by its controller;
while no command comes it holds still and its camera (and lidar) keep publishing at their
rate in wall time, stamped with the unchanged sim time. So an image the node waits for at
a decision is the state replay renders. The simulator's truth (object poses) is read only
to score the task at the end (:func:`score`).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from smccli.execute.sensing import Sensors
from smccli.logs.topic_map import TopicMap
from smccli.perception.scan import Scan2D
from smccli.world.geometry import quat_yaw
from smccli.world.scene import Layout, Scene
from smccli.world.sensors import CameraFrame, JointState, PoiCommand
from smccli.world.sim import Sim

CAMERA_FRAME = "camera_color_optical_frame"
"""The camera's TF frame (optical: x right, y down, z forward)."""
LIDAR_FRAME = "lidar"


def sim_topic_map(scene: Scene) -> dict[str, Any]:
    """The topic map (``schemas/topic_map.schema.json``) of what ``smc sim --ros1``
    publishes and takes for ``scene``: raw colour (rgb8) and depth (32FC1 [m]) images, the
    POI as a TF frame, the lidar and scale where the robot and scene have them."""
    robot = scene.robot
    topics: dict[str, Any] = {
        "joint_states": "/joint_states",
        "poi": {"frame": "tool" if robot.arm_joints else "base_footprint"},
        "color": "/camera/color/image_raw",
        "depth": "/camera/depth/image_raw",
        "camera_info": "/camera/color/camera_info",
    }
    if any(s.type == "lidar" for s in robot.sensors):
        topics["lidar"] = "/scan"
    if scene.scale is not None:
        topics["weight"] = "/scale/weight"
    run: dict[str, Any] = {"command": "/smc/poi_target"}
    if robot.gripper is not None:
        run["gripper"] = "/gripper/command"
    return {"scene": scene.name, "world_frame": "world", "topics": topics, "run": run}


@dataclass(frozen=True, slots=True)
class Readings:
    """What the robot publishes at one instant (sim time ``t``)."""

    t: float
    joints: JointState
    poi: np.ndarray
    """POI ``[x, y, z, yaw]`` in the world frame (an arm's tool, a base's odometry)."""
    frame: CameraFrame | None = None
    scan: Scan2D | None = None
    lidar_pose: np.ndarray | None = None
    """``[x, y, yaw]`` of the lidar when ``scan`` was taken."""
    weight: float | None = None


class SimRobot:
    """A simulated robot stepped by the commands it receives (see the module's docstring)."""

    def __init__(self, scene: Scene, layout: Layout, topic_map: TopicMap) -> None:
        self.scene, self.layout, self.map = scene, layout, topic_map
        self.sim = Sim(scene, layout)
        self.sensors = Sensors(self.sim)
        self.sim.start_camera()
        self.cond = threading.Condition()
        self.targets: dict[int, np.ndarray] = {}
        """Stamp [ns] -> POI target ``[x, y, z, yaw]`` (``run.command``)."""
        self.arm: dict[int, np.ndarray] = {}
        """Stamp [ns] -> the arm's joint targets in the robot file's order (``run.arm``)."""
        self.grips: dict[int, float] = {}
        self._last: tuple[PoiCommand, np.ndarray | None] | None = None
        self.steps = 0
        self.camera_every = max(1, round(1 / (scene.camera.rate * self.sim.control_period)))
        """Control periods between two camera images while the robot moves."""
        self._grip = 1.0
        self.takes_gripper = (
            scene.robot.gripper is not None
            and topic_map.run is not None
            and topic_map.run.gripper is not None
        )

    def on_target(self, stamp_ns: int, position: Any, quaternion: Any) -> None:
        """A POI target (position (3,), quaternion ``[w, x, y, z]``) for the period ``stamp_ns``."""
        yaw = quat_yaw(quaternion)
        with self.cond:
            self.targets[stamp_ns] = np.array([*position, yaw], dtype=float)
            self.cond.notify_all()

    def on_gripper(self, stamp_ns: int, names: list[str], positions: list[float]) -> None:
        """A finger command: the opening of the gripper's joints' mean target."""
        g = self.scene.robot.gripper
        if g is None:
            return
        ours = [self.map.joints.get(n, n) for n in names]
        q = [p for n, p in zip(ours, positions, strict=False) if n in g.joints]
        if not q:
            return
        with self.cond:
            self.grips[stamp_ns] = g.opening(np.array(q))
            self.cond.notify_all()

    def on_arm(self, stamp_ns: int, names: list[str], positions: list[float]) -> None:
        """The arm's joint targets for the period ``stamp_ns`` (driver names: renamed by
        the map's ``joints``); a message without every arm joint is ignored."""
        given = dict(zip((self.map.joints.get(n, n) for n in names), positions, strict=False))
        joints = self.scene.robot.arm_joints
        if not joints or any(j not in given for j in joints):
            return
        with self.cond:
            self.arm[stamp_ns] = np.array([given[j] for j in joints], dtype=float)
            self.cond.notify_all()

    def next_command(self) -> tuple[PoiCommand, np.ndarray | None] | None:
        """The oldest complete command (lock held): a POI target or the arm's joint
        targets, and its gripper command when the robot takes one; None when none is
        complete. Older incomplete ones are dropped (superseded)."""
        pending = self.arm if self.arm else self.targets
        for stamp in sorted(pending):
            if self.takes_gripper and stamp not in self.grips:
                continue
            value = pending.pop(stamp)
            self._grip = self.grips.pop(stamp, self._grip)
            for old in [s for s in pending if s < stamp]:
                del pending[old]
            if pending is self.arm:
                return PoiCommand(self.sim.t, self.sim.poi(), self._grip), value
            return PoiCommand(self.sim.t, value, self._grip), None
        return None

    def step(self, cmd: PoiCommand, arm_q: np.ndarray | None = None) -> Readings:
        """Execute one control period of ``cmd`` (or of the arm's joint targets ``arm_q``);
        the readings after it (the camera and lidar at their rate)."""
        if arm_q is None:
            self.sensors.step(cmd)
        else:  # the driver hands joint targets to the servos
            self.sim.step(cmd, arm_q=arm_q)
        self._last = (cmd, arm_q)
        self.steps += 1
        return self.readings(sensing=self.steps % self.camera_every == 0)

    def readings(self, sensing: bool) -> Readings:
        """The joints and the POI now; with ``sensing`` the camera, lidar and scale too."""
        s = self.sensors
        frame = scan = pose = None
        if sensing:
            frame = s.render_camera()
            if s.has_lidar:
                scan, pose = s.lidar(), s.lidar_pose()
        return Readings(s.t, s.joint_state(), s.poi(), frame, scan, pose, s.weight())

    def score(self, settle_s: float = 1.0) -> dict[str, Any]:
        """After the run: the scene settles ``settle_s`` holding the last command, then its
        success criterion from the simulator's truth (evaluation only)."""
        from smccli.world.truth import Truth

        if self._last is not None and self._last[1] is not None:  # hold the joint targets
            for _ in range(round(settle_s / self.sim.control_period)):
                self.sim.step(*self._last)  # type: ignore[arg-type]
        else:
            self.sim.settle(settle_s)
        truth = Truth(self.sim)
        success = truth.success()
        final = {o.name: [float(v) for v in truth.object_pose(o.name)] for o in self.scene.objects}
        return {
            "scene": self.scene.name,
            "layout": {k: [float(v) for v in p] for k, p in self.layout.items()},
            "success": bool(success),
            "reason": success.reason,
            "steps": self.steps,
            "t": self.sim.t,
            "final_poses": final,
        }

    def close(self) -> None:
        self.sim.close()
