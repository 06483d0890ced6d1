"""The simulation: a scene in MuJoCo, stepped one control period at a time, and its sensors.

Everything the robot perceives goes through :meth:`Sim.render_camera`, :meth:`Sim.lidar`,
:meth:`Sim.weight`, :meth:`Sim.joint_state` and :meth:`Sim.poi`. What no sensor gives (object
poses, the success criterion) is read by evaluation alone, through
:class:`smccli.world.truth.Truth`.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import mujoco
import numpy as np

from smccli.errors import SceneError
from smccli.world.camera import CameraRenderer
from smccli.world.controller import CartesianController, poi_pose
from smccli.world.geometry import (
    between,
    compose,
    planar_se3,
    pose_floats,
    wrap,
    yaw_of,
)
from smccli.world.layout import nominal_layout, place_objects
from smccli.world.lidar import Lidar, LidarReading
from smccli.world.marker import MARKER_BODY, MARKER_RADIUS, with_target_marker
from smccli.world.noise import CameraNoise, NoisySensors
from smccli.world.robot import robot_only_groups
from smccli.world.robot_model import RobotModel
from smccli.world.scene import HIDDEN_GROUP, ROBOT_KEY, Layout, ObjectSpec, Scene
from smccli.world.sensors import (
    CONTROL_PERIOD,
    CameraFrame,
    DrawingFrame,
    JointState,
    PoiCommand,
    RobotGeometry,
)

__all__ = ["CONTROL_PERIOD", "HIDDEN_GROUP", "MARKER_RADIUS", "OdometryDrift", "Sim"]
"""Besides the simulator: the constants its users read here (the teleop viewer's)."""

GRAVITY = 9.81
PARK_DEPTH = 1.0
"""How far below the scene's lowest geom objects absent from a layout are parked [m]."""
PARK_GAP = 0.1
"""Space between two parked objects [m]."""


@dataclass(frozen=True, slots=True)
class OdometryDrift:
    """Wheel odometry's error, added on purpose (docs/design.md 9: odometry = joint readings).

    Each control period's body-frame motion is integrated with its translation scaled by
    ``1 + scale`` and its heading off by ``yaw_per_metre`` per metre travelled, so the
    error grows with the distance driven, as real odometry's does."""

    scale: float = 0.02
    """Relative error of the travelled distance."""
    yaw_per_metre: float = 0.02
    """Heading error per metre travelled [rad/m]."""


class Sim:
    """A scene in MuJoCo with the Cartesian controller between commands and joint servos.

    A mobile base's POI is its odometry: the joint readings, or with ``drift`` the motion
    integrated with that error. Base targets are then in odometry's frame, as a real base
    controller's are; :meth:`smccli.world.truth.Truth.base_pose` (evaluation only) is the
    truth."""

    def __init__(
        self,
        scene: Scene,
        layout: Layout | None = None,
        base_pose: np.ndarray | None = None,
        drift: OdometryDrift | None = None,
        *,
        target_marker: bool = False,
    ) -> None:
        self.scene = scene
        self.drift = drift
        self.model = scene.model() if not target_marker else with_target_marker(scene)
        self.marker_id = (
            mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, MARKER_BODY)
            if target_marker
            else -1
        )
        """The teleop target marker's body (a mocap body the person drags in the viewer),
        or -1: see :func:`smccli.world.marker.with_target_marker`."""
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.control_period = CONTROL_PERIOD
        self.n_substeps = max(1, round(CONTROL_PERIOD / m.opt.timestep))
        robot = self.robot = scene.robot
        self.mobile_manipulator = robot.base is not None and bool(robot.arm_joints)
        """Base and arm: two POIs, the base's pose (odometry) and the end effector in the
        base's frame (docs/design.md 9)."""
        self.poi_id = self._id(mujoco.mjtObj.mjOBJ_SITE, robot.poi)
        # A mobile manipulator's controller solves in the base's frame: its own copy of the
        # model keeps the base joints at zero, where the base frame is the model's origin.
        self.controller = (
            CartesianController(m, robot, control_period=CONTROL_PERIOD)
            if robot.arm_joints
            else None
        )
        self._index_robot()
        self._index_sensors()
        self._index_world()
        self._robot: RobotModel | None = None
        self._last = PoiCommand(0.0, np.zeros(4), 1.0)
        # A layout moves static bodies in the model itself: reset starts from these, so a
        # simulator reset for a new layout is the one built for it (campaign workers keep
        # theirs).
        self._body_pos0 = m.body_pos.copy()
        self._body_quat0 = m.body_quat.copy()
        # Parking takes an object out of contact and out of the sensors' groups: reset puts
        # them back.
        self._geom_contype0 = m.geom_contype.copy()
        self._geom_conaffinity0 = m.geom_conaffinity.copy()
        self._geom_group0 = m.geom_group.copy()
        self.park_z = _lowest_point(m) - PARK_DEPTH
        """Parked objects hang this far down [m]: under every geom of the scene, so an
        object above it is in the scene (:func:`smccli.execute.verify.initial_layout`)."""
        self._parked: tuple[int, ...] = ()
        self.reset(layout, base_pose)

    def _index_robot(self) -> None:
        """Where the robot's joints sit in qpos/qvel (base, arm, fingers, in the robot
        file's order) and its actuators' ids."""
        m, robot = self.model, self.robot
        act = mujoco.mjtObj.mjOBJ_ACTUATOR
        base = robot.base.joints if robot.base else ()
        fingers = robot.gripper.joints if robot.gripper else ()
        self._jnames = robot.joint_names
        joints = [self._id(mujoco.mjtObj.mjOBJ_JOINT, n) for n in self._jnames]
        self._jq = np.array([m.jnt_qposadr[j] for j in joints], dtype=int)
        self._jv = np.array([m.jnt_dofadr[j] for j in joints], dtype=int)
        n_base, n_arm = len(base), len(robot.arm_joints)
        self.base_qpos = self._jq[:n_base]
        """qpos addresses of a mobile base's joints ``x, y, yaw`` (empty for an arm)."""
        self._arm_q = self._jq[n_base : n_base + n_arm]
        self._finger_q = self._jq[n_base + n_arm :]
        self._finger_v = self._jv[n_base + n_arm :]
        self._base_act = np.array(
            [self._id(act, n) for n in (robot.base.actuators if robot.base else ())], dtype=int
        )
        self._base_body = (
            int(m.jnt_bodyid[self._id(mujoco.mjtObj.mjOBJ_JOINT, base[-1])]) if base else -1
        )
        self._arm_act = np.array([self._id(act, n) for n in robot.arm_actuators], dtype=int)
        self._grip_act = self._id(act, robot.gripper.actuator) if robot.gripper else -1
        assert len(fingers) == len(self._finger_q)

    def _index_sensors(self) -> None:
        """The lidar (and its site), the sensor camera and the scale's force sensor."""
        m, scene = self.model, self.scene
        self._lidar = None
        self._lidar_site = -1
        for s in self.robot.sensors:
            if s.type == "lidar":
                own = robot_only_groups(self.robot, m)
                self._lidar = Lidar(m, s.target, ignore_group=(*own, HIDDEN_GROUP))
                self._lidar_site = self._id(mujoco.mjtObj.mjOBJ_SITE, s.target)
        self._cam_id = self._id(mujoco.mjtObj.mjOBJ_CAMERA, scene.camera.name)
        self._camera = CameraRenderer(
            self.model, self._cam_id, scene.camera.height, scene.camera.width
        )
        self._scale_sensor = None
        if scene.scale is not None:
            sid = self._id(mujoco.mjtObj.mjOBJ_SENSOR, f"{scene.scale}_force")
            self._scale_sensor = m.sensor_adr[sid]

    def _index_world(self) -> None:
        """The bodies a layout places (objects, furniture) and the free objects' joints."""
        m, scene = self.model, self.scene
        body = mujoco.mjtObj.mjOBJ_BODY
        self.bodies = {o.name: self._id(body, o.name) for o in scene.objects}
        """Body id of each object, then of each piece of furniture (moved by the layout
        as fixed objects are)."""
        for f in scene.furniture:
            self.bodies[f.name] = self._id(body, f.name)
        self.free_joints: dict[str, tuple[int, int]] = {}
        """A free object's joint: its (qpos, qvel) addresses."""
        for o in scene.objects:
            if not o.fixed:
                jid = m.body_jntadr[self.bodies[o.name]]
                self.free_joints[o.name] = (m.jnt_qposadr[jid], m.jnt_dofadr[jid])

    def _id(self, kind: mujoco.mjtObj, name: str) -> int:
        return model_id(self.model, kind, name, self.scene.name)

    # --- state -------------------------------------------------------------------------

    def reset(
        self,
        layout: Layout | None = None,
        base_pose: np.ndarray | None = None,
        noise_seed: int | None = None,
    ) -> None:
        """Robot at home with the gripper open, objects at ``layout`` (default nominal), a
        mobile base at ``base_pose`` ``[x, y, yaw]`` [m, m, rad] (default: the layout's
        :data:`ROBOT_KEY`, else the origin). The sensor errors of the episode
        (:mod:`smccli.world.noise`) are drawn with ``noise_seed`` (default: from the
        layout, so a campaign's trials differ and each is reproducible)."""
        m, d = self.model, self.data
        m.body_pos[:] = self._body_pos0
        m.body_quat[:] = self._body_quat0
        m.geom_contype[:] = self._geom_contype0
        m.geom_conaffinity[:] = self._geom_conaffinity0
        m.geom_group[:] = self._geom_group0
        mujoco.mj_resetData(m, d)
        if layout is None:
            # A scene with variants has look-alike objects sharing a nominal pose: show one.
            first = self.scene.variants[0][0] if self.scene.variants else None
            layout = nominal_layout(self.scene, first)
        layout = dict(layout)
        if noise_seed is None:
            noise_seed = _layout_seed(layout)
        self.sensor_noise = NoisySensors(self.scene.noise, noise_seed)
        """This episode's sensor errors."""
        start = layout.pop(ROBOT_KEY, None)
        if base_pose is None:
            base_pose = np.zeros(3) if start is None else np.array([start[0], start[1], start[3]])
        base_pose = np.asarray(base_pose, dtype=float)
        unknown = [name for name in layout if name not in self.bodies]
        if unknown:
            raise SceneError(
                f"layout: no object {unknown[0]!r} in scene {self.scene.name}"
                f" ({', '.join(self.bodies)})"
            )
        place_objects(m, d, layout)
        # Objects the layout leaves out (another variant's) leave the world.
        self._park([o for o in self.scene.objects if o.name not in layout])
        self.present = tuple(n for n in layout)
        """Names of the objects the layout placed (for evaluation and the operator, who see
        the world)."""
        if self.controller is not None:
            home = self.robot.home_array()
            d.qpos[self._arm_q] = home
            self.controller.reset(home)
            d.ctrl[self._arm_act] = home
        if self.robot.gripper is not None:
            d.qpos[self._finger_q] = self.robot.gripper.open
            g = self.robot.gripper  # the command in the actuator's units (any: 0-255 ...)
            d.ctrl[self._grip_act] = g.commands[1] if g.commands else g.open
        if len(self.base_qpos):
            d.qpos[self.base_qpos] = base_pose
            d.ctrl[self._base_act] = base_pose
        mujoco.mj_forward(m, d)
        self._odom = base_pose.copy()
        """Odometry's base pose (x, y, yaw) [m, m, rad], yaw unwrapped."""
        self._odom_truth = base_pose.copy()
        """The true pose at the last odometry update."""
        self._last = PoiCommand(
            0.0, self.poi(), 1.0, base=self.base_odometry() if self.mobile_manipulator else None
        )
        # Tare: the empty scale's reading is the platform's own weight.
        self._tare = 0.0 if self._scale_sensor is None else self._scale_force()

    def _park(self, objects: list[ObjectSpec]) -> None:
        """Take ``objects`` (absent from the layout: another variant's) out of the world:
        no contacts, in :data:`HIDDEN_GROUP`, side by side :data:`PARK_DEPTH` under the
        scene's lowest geom; a free one held at rest by a force that cancels its weight.

        Resting them on a floor would need free floor out of every sensor's view, which a
        mobile robot's scenes do not have; and a floor plane is a half-space in MuJoCo: an
        object parked under one is thrown out of it."""
        m, d = self.model, self.data
        x = float(m.stat.center[0])
        parked = []
        for o in objects:
            root = self.bodies[o.name]
            bodies = [b for b in range(m.nbody) if _descends(m, b, root)]
            geoms = np.flatnonzero(np.isin(m.geom_bodyid, bodies))
            m.geom_contype[geoms] = 0
            m.geom_conaffinity[geoms] = 0
            m.geom_group[geoms] = HIDDEN_GROUP
            radius = float(m.geom_rbound[geoms].max(initial=0.1))
            at = [x + radius, float(m.stat.center[1]), self.park_z]
            x += 2 * radius + PARK_GAP
            if o.name not in self.free_joints:  # a static body (a poster): move it
                m.body_pos[root], m.body_quat[root] = at, [1, 0, 0, 0]
                continue
            qa, _ = self.free_joints[o.name]
            d.qpos[qa : qa + 7] = [*at, 1, 0, 0, 0]
            parked += bodies
        self._parked = tuple(parked)
        self._hold_parked()

    def _hold_parked(self) -> None:
        """Each parked body's weight cancelled at its centre of mass (xfrc_applied acts
        there), so it stays where it was put (gravcomp would need a model compiled with it)."""
        for b in self._parked:
            weight = -self.model.body_mass[b] * self.model.opt.gravity[2]
            self.data.xfrc_applied[b] = [0.0, 0.0, weight, 0.0, 0.0, 0.0]

    def clear_pushes(self) -> None:
        """Remove forces a person applied in the viewer (a Ctrl-drag), keeping what holds
        parked objects in place."""
        self.data.xfrc_applied[:] = 0.0
        self._hold_parked()

    @property
    def t(self) -> float:
        """Simulation time [s]."""
        return float(self.data.time)

    def step(self, cmd: PoiCommand, arm_q: np.ndarray | None = None) -> None:
        """Advance one control period (10 ms) towards ``cmd``.

        An arm's POI target goes through the Cartesian controller; a mobile base's
        ``[x, y, z, yaw]`` (z ignored) is its joints' target directly, the yaw unwrapped to
        the turn nearest the current one (the hinge is continuous). ``arm_q``: the arm's
        joint targets (n_arm,) [rad] given directly, for a robot commanded in joint space
        (``smc sim --ros1`` with ``run.arm``): the servos take them and the controller
        restarts from them.
        """
        if self.mobile_manipulator and cmd.base is None:  # the base holds its last target
            cmd = PoiCommand(cmd.t, cmd.target, cmd.gripper, base=self._last.base)
        self._last = cmd
        target = np.asarray(cmd.target, float)
        if arm_q is not None and self.controller is not None:
            self.controller.reset(arm_q)
            self.data.ctrl[self._arm_act] = self.controller.q
        elif self.controller is not None:
            self.data.ctrl[self._arm_act] = self.controller.update(target)
        if self.robot.gripper is not None:
            self.data.ctrl[self._grip_act] = self.robot.gripper.target(cmd.gripper)
        if len(self._base_act):
            base = (
                np.asarray(cmd.base, float)
                if self.mobile_manipulator and cmd.base is not None
                else (target[0], target[1], target[3])
            )
            # The target is in odometry's frame: the same place relative to the robot in
            # the joints' frame (identity without drift). compose(truth, inverse(odom)),
            # then compose(that, base), on Python floats: the same bits without the arrays,
            # whose overhead was 13 us a step beside mj_step's 30 (the rooms' base).
            no_odom = pose_floats(self._odom, (0.0, 0.0, 0.0), inverse_a=True)
            x, y, yaw = pose_floats(pose_floats(self._odom_truth, no_odom), base)
            yaw_now = float(self.data.qpos[self.base_qpos[2]])
            yaw = yaw_now + wrap(float(yaw) - yaw_now)
            self.data.ctrl[self._base_act] = [x, y, yaw]
        mujoco.mj_step(self.model, self.data, nstep=self.n_substeps)
        if len(self.base_qpos):
            self._integrate_odometry()

    def _integrate_odometry(self) -> None:
        """Add this period's body-frame motion to odometry, with the drift's error."""
        now = self.data.qpos[self.base_qpos].astype(float)  # a copy: MuJoCo's own moves on
        if self.drift is None:  # neither is changed in place: they may share
            self._odom = self._odom_truth = now
            return
        delta = between(self._odom_truth, now)  # a period's motion: in (-pi, pi] already
        dist = math.hypot(delta[0], delta[1])
        k = 1.0 + self.drift.scale
        err = np.array([k * delta[0], k * delta[1], delta[2] + self.drift.yaw_per_metre * dist])
        self._odom = compose(self._odom, err)
        self._odom_truth = now.copy()

    def settle(self, seconds: float) -> None:
        """Hold the last command for ``seconds`` [s] (lets objects come to rest)."""
        last = self._last
        for _ in range(max(0, round(seconds / self.control_period))):
            self.step(PoiCommand(self.t, last.target, last.gripper, base=last.base))

    # --- robot sensors -----------------------------------------------------------------

    def poi(self) -> np.ndarray:
        """POI ``[x, y, z, yaw]`` [m, m, m, rad], yaw in (−π, π]; a mobile base's is its
        odometry (z = 0); a mobile manipulator's is the end effector in the base's frame
        (from the arm's joints: the base's pose plays no part)."""
        if self.mobile_manipulator:
            d, b = self.data, self._base_body
            R_b = d.xmat[b].reshape(3, 3)
            R = R_b.T @ d.site_xmat[self.poi_id].reshape(3, 3)
            p = R_b.T @ (d.site_xpos[self.poi_id] - d.xpos[b])
            return np.array([*p, yaw_of(R)])
        if len(self.base_qpos):
            x, y, yaw = self.base_odometry()
            return (
                np.array([x, y, 0.0, yaw])
                if self.drift is not None
                else poi_pose(self.data, self.poi_id)
            )
        return poi_pose(self.data, self.poi_id)

    def poi_frame(self) -> tuple[np.ndarray, np.ndarray]:
        """The frame POI targets are given in, as world ``(R (3, 3), p (3,))``: the base's
        body for a mobile manipulator's hand, else the world (display only: the teleop
        viewer draws targets with it)."""
        if self.mobile_manipulator:
            b = self._base_body
            return self.data.xmat[b].reshape(3, 3).copy(), self.data.xpos[b].copy()
        return np.eye(3), np.zeros(3)

    def base_odometry(self) -> np.ndarray:
        """A mobile base's pose ``[x, y, yaw]`` from odometry [m, m, rad], yaw in (−π, π]."""
        x, y, yaw = self._odom
        return np.array([x, y, wrap(float(yaw))])

    def lidar_height(self) -> float:
        """Height of the lidar's scan plane above the floor [m] (a fixed mounting)."""
        return float(self.data.site_xpos[self._lidar_site][2]) if self._lidar_site >= 0 else 0.0

    def lidar_pose(self) -> np.ndarray | None:
        """The lidar's planar pose ``[x, y, yaw]`` in odometry's frame (the POI composed
        with the lidar's fixed mounting on the robot), None without a lidar."""
        if self._lidar_site < 0:
            return None
        d = self.data
        site = np.array([*d.site_xpos[self._lidar_site][:2], yaw_of(d.site_xmat[self._lidar_site])])
        mount = between(self._base_world(), site)
        mount[2] = wrap(mount[2])
        out = compose(self.base_odometry(), mount)
        out[2] = wrap(out[2])
        return out

    def gripper_opening(self) -> float:
        """Distance between the finger pads over its maximum, in [0, 1] (1 without one)."""
        if self.robot.gripper is None:
            return 1.0
        return self.robot.gripper.opening(self.data.qpos[self._finger_q])

    def gripper_speed(self) -> float:
        """Rate of change of :meth:`gripper_opening` [1/s]."""
        if self.robot.gripper is None:
            return 0.0
        return self.robot.gripper.opening_rate(self.data.qvel[self._finger_v])

    def lidar(self) -> LidarReading | None:
        """A scan of the robot's lidar (its own geoms left out), or None without one."""
        return None if self._lidar is None else self.sensor_noise.scan(self._lidar.scan(self.data))

    def joint_state(self) -> JointState:
        """Positions, velocities and actuator efforts of the arm and finger joints."""
        d = self.data
        return JointState(
            t=self.t,
            names=self._jnames,
            position=d.qpos[self._jq].copy(),
            velocity=d.qvel[self._jv].copy(),
            effort=d.qfrc_actuator[self._jv].copy(),
        )

    def weight(self) -> float | None:
        """Mass resting on the scale [kg], tared; None if the scene has no scale."""
        if self._scale_sensor is None:
            return None
        return self.sensor_noise.weight(self.t, (self._scale_force() - self._tare) / GRAVITY)

    def _scale_force(self) -> float:
        # The force sensor gives what the platform's parent exerts on it, in the site frame
        # (z up): at rest it carries the platform and everything on it.
        a = self._scale_sensor
        return float(self.data.sensordata[a + 2])  # type: ignore[operator]

    def robot_geometry(self) -> RobotGeometry:
        """Bounding spheres of the robot's moving links from its own kinematics (self-filter).

        Computed as compile computes it from logged joint states (a kinematic copy of the
        robot posed from the joint readings, :mod:`smccli.world.robot_model`), so replay perceives
        exactly as compile did.
        """
        js = self.joint_state()
        if self._robot is None:
            self._robot = RobotModel.from_mjcf(self.scene.mjcf, js.names, dict(self.scene.assets))
        return self._robot.geometry_for(js.position)

    # --- camera ------------------------------------------------------------------------

    @property
    def camera_windows(self) -> bool:
        """Whether :meth:`render_camera` of a region draws that region alone and nothing
        else: a camera without noise. A noisy one draws the noise of a whole frame at
        every frame (a frame more changes every later draw) and its whole depth."""
        return self.sensor_noise.noise.camera == CameraNoise()

    def render_camera(
        self,
        region: tuple[int, int, int, int] | None = None,
        colour: bool = True,
        *,
        colour_later: bool = False,
    ) -> CameraFrame:
        """RGB and metric depth (along the optical axis) from the scene's sensor camera.

        ``region`` ``(v0, v1, u0, u1)``: only rows ``v0:v1`` and columns ``u0:u1`` are
        rendered (a look at one object: a third of a frame's time), the rest of the image
        holds no reading (depth 0, black). Its colours are the whole frame's but for a rare
        pixel on an edge, its depths may differ from them in the last bits (a micrometre:
        another projection matrix, :meth:`CameraRenderer.region`).
        A camera with noise renders the whole frame's depth whatever ``region`` says (the
        noise's draws depend on which pixels of it have a reading, its holes on the depth
        edges) and the window's colours alone (:meth:`CameraRenderer.colour_region`), and
        adds noise to the window alone: its depths are those of the whole noisy frame to
        the bit, its colours too but for a rare pixel on an edge, and every later draw is
        the same (:meth:`NoisySensors.frame`). Without ``colour`` a camera without noise
        draws the window's depth alone (its image black).
        With ``colour_later`` a whole frame without noise is a
        :class:`~smccli.world.sensors.DrawingFrame` (its colours drawn while the caller
        works on its depth, read at their first use, in this thread); a noisy camera's are
        drawn while its noise is drawn (:meth:`NoisySensors.draws`).
        """
        cam, noise = self._camera, self.sensor_noise
        K, T = self.camera_matrix(), self.camera_pose()
        if region is not None and self.camera_windows:
            rgb, depth = cam.region(self.data, region, colour)
            return CameraFrame(self.t, rgb, depth, K, T)
        drawn = cam.render(self.data) if region is None else cam.colour_region(self.data, region)
        fetch, depth = drawn
        if self.camera_windows:
            if colour_later:
                return DrawingFrame(self.t, None, depth, K, T, fetch=fetch)
            return CameraFrame(self.t, fetch(), depth, K, T)
        draws = noise.draws(depth)  # while the colours are drawn
        return noise.frame(CameraFrame(self.t, fetch(), depth, K, T), region, draws)

    def camera_near(self) -> float:
        """The camera's near clipping distance [m]: no depth reading is nearer."""
        return self._camera.near

    def start_camera(self) -> None:
        """Build the camera's renderer and render one frame, discarded, unless it runs
        already: a GL context's first frames are slow (shaders, buffers), and a decision's
        latency should not include them. Draws no sensor noise, so an episode's readings do
        not depend on whether its simulator is new or reset."""
        self._camera.start(self.data)

    def camera_matrix(self) -> np.ndarray:
        """Pinhole intrinsics from the camera's vertical field of view, shape (3, 3) [px].

        Pixel centres are at integer coordinates (OpenCV convention).
        """
        cam = self.scene.camera
        fovy = math.radians(self.model.cam_fovy[self._cam_id])
        f = 0.5 * cam.height / math.tan(fovy / 2)
        return np.array([[f, 0.0, (cam.width - 1) / 2], [0.0, f, (cam.height - 1) / 2], [0, 0, 1]])

    def camera_pose(self) -> np.ndarray:
        """T_world_camera, shape (4, 4), optical frame (x right, y down, z forward). A camera
        on a mobile base: its mounting on the robot composed with odometry's base pose (the
        world frame is odometry's, as for the lidar)."""
        T = np.eye(4)
        # MuJoCo cameras look along −z with y up: flip y and z for the optical convention.
        T[:3, :3] = self.data.cam_xmat[self._cam_id].reshape(3, 3) @ np.diag([1.0, -1.0, -1.0])
        T[:3, 3] = self.data.cam_xpos[self._cam_id]
        if len(self.base_qpos) and self.drift is not None:
            T = planar_se3(self.base_odometry()) @ np.linalg.inv(planar_se3(self._base_world())) @ T
        return T

    def _base_world(self) -> np.ndarray:
        """The base body's planar pose from the joints ``[x, y, yaw]`` (what odometry
        integrates; used only to express mountings relative to the base)."""
        d, b = self.data, self._base_body
        return np.array([d.xpos[b][0], d.xpos[b][1], yaw_of(d.xmat[b])])

    def close(self) -> None:
        """Free the renderer's GL context."""
        self._camera.close()


def model_id(model: mujoco.MjModel, kind: mujoco.mjtObj, name: str, scene: str) -> int:
    """The id of the ``kind`` called ``name`` in ``model`` (of scene ``scene``); SceneError
    when the model has none."""
    i = mujoco.mj_name2id(model, kind, name)
    if i < 0:
        raise SceneError(f"scene {scene}: model has no {kind.name[6:].lower()} {name!r}")
    return i


def _descends(m: mujoco.MjModel, body: int, root: int) -> bool:
    """Whether ``body`` is ``root`` or below it in the kinematic tree."""
    while body > 0:
        if body == root:
            return True
        body = int(m.body_parentid[body])
    return False


def _lowest_point(m: mujoco.MjModel) -> float:
    """The lowest z [m] of the model's geoms at its initial state (a plane: its height,
    a geom: its centre less its bounding radius)."""
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    z = d.geom_xpos[:, 2] - m.geom_rbound
    return float(z.min(initial=0.0))


def _layout_seed(layout: Layout) -> int:
    """A seed from a layout's poses (its names and numbers, in order)."""
    text = repr(sorted((k, tuple(float(x) for x in v)) for k, v in layout.items()))
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], "little")
