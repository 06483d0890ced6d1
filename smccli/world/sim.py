"""The simulation: a scene in MuJoCo, stepped one control period at a time, and its sensors.

Everything the robot perceives goes through :meth:`Sim.render_camera`, :meth:`Sim.weight`,
:meth:`Sim.joint_state` and :meth:`Sim.poi`. :meth:`Sim.ground_truth` and :meth:`Sim.success`
read simulator state and are for evaluation only.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import mujoco
import numpy as np

from smccli.errors import SceneError
from smccli.world.controller import CartesianController, poi_pose
from smccli.world.geometry import (
    between,
    compose,
    inverse,
    planar_se3,
    wrap,
    yaw_of,
)
from smccli.world.layout import nominal_layout, place_objects
from smccli.world.lidar import Lidar, LidarReading
from smccli.world.noise import NoisySensors
from smccli.world.robot import robot_geoms
from smccli.world.robot_model import RobotModel
from smccli.world.scene import (
    HIDDEN_GROUP,
    ROBOT_KEY,
    Condition,
    Group,
    Layout,
    ObjectSpec,
    Scene,
)
from smccli.world.sensors import CameraFrame, JointState, PoiCommand, RobotGeometry

ON_TOP_TOL = 0.015
"""How far an object's lowest corner may be from the target's top face to rest on it [m]."""
INSIDE_TOL = 0.005
"""How far below the container's bottom an object's lowest corner may be [m] (contact
penetration)."""
REST_SPEED = (0.02, 0.2)
"""At rest: linear [m/s] and angular [rad/s] speed below these."""
MARKER_BODY = "smc_target"
"""The teleop target marker's body (``Sim(target_marker=True)``)."""
MARKER_RADIUS = 0.025
"""Its sphere's radius [m]: big enough to pick with the mouse."""
CONTROL_PERIOD = 0.01
"""Control period [s] (100 Hz); the physics timestep comes from the model (2 ms)."""
GRAVITY = 9.81
PARK_DEPTH = 1.0
"""How far below the scene's lowest geom objects absent from a layout are parked [m]."""
PARK_GAP = 0.1
"""Space between two parked objects [m]."""


@dataclass(frozen=True, slots=True)
class Success:
    """Outcome of the scene's success criterion; truthy when the task succeeded."""

    ok: bool
    """Whether a task's criterion holds."""
    reason: str
    """Which task and condition held, or why none did."""
    criteria: tuple[tuple[str, str, bool], ...] = ()
    """Every condition tried: (task, what it found, whether it held)."""

    def __bool__(self) -> bool:
        return self.ok


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
    controller's are; :meth:`base_pose` (evaluation only) is the truth."""

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
        self.model = scene.model() if not target_marker else _with_target_marker(scene)
        self.marker_id = (
            mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, MARKER_BODY)
            if target_marker
            else -1
        )
        """The teleop target marker's body (a mocap body the person drags in the viewer),
        or -1: see :func:`_with_target_marker`."""
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
        act = mujoco.mjtObj.mjOBJ_ACTUATOR
        base = robot.base.joints if robot.base else ()
        fingers = robot.gripper.joints if robot.gripper else ()
        self._jnames = robot.joint_names
        joints = [self._id(mujoco.mjtObj.mjOBJ_JOINT, n) for n in self._jnames]
        self._jq = np.array([m.jnt_qposadr[j] for j in joints], dtype=int)
        self._jv = np.array([m.jnt_dofadr[j] for j in joints], dtype=int)
        n_base, n_arm = len(base), len(robot.arm_joints)
        self._base_q = self._jq[:n_base]
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
        self._lidar = None
        self._lidar_site = -1
        for s in robot.sensors:
            if s.type == "lidar":
                self._lidar = Lidar(m, s.target, ignore_group=(robot.geom_group, HIDDEN_GROUP))
                self._lidar_site = self._id(mujoco.mjtObj.mjOBJ_SITE, s.target)
        self._cam_id = self._id(mujoco.mjtObj.mjOBJ_CAMERA, scene.camera.name)
        self._body = {o.name: self._id(mujoco.mjtObj.mjOBJ_BODY, o.name) for o in scene.objects}
        for f in scene.furniture:  # moved by the layout as fixed objects are
            self._body[f.name] = self._id(mujoco.mjtObj.mjOBJ_BODY, f.name)
        self._free_qadr = {}
        for o in scene.objects:
            if not o.fixed:
                jid = m.body_jntadr[self._body[o.name]]
                self._free_qadr[o.name] = (m.jnt_qposadr[jid], m.jnt_dofadr[jid])
        self._scale_sensor = None
        if scene.scale is not None:
            sid = self._id(mujoco.mjtObj.mjOBJ_SENSOR, f"{scene.scale}_force")
            self._scale_sensor = m.sensor_adr[sid]
        self._robot_geoms = robot_geoms(robot, m)
        self._renderer: mujoco.Renderer | None = None
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

    def _id(self, kind: mujoco.mjtObj, name: str) -> int:
        i = mujoco.mj_name2id(self.model, kind, name)
        if i < 0:
            raise SceneError(
                f"scene {self.scene.name}: model has no {kind.name[6:].lower()} {name!r}"
            )
        return i

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
        unknown = [name for name in layout if name not in self._body]
        if unknown:
            raise SceneError(
                f"layout: no object {unknown[0]!r} in scene {self.scene.name}"
                f" ({', '.join(self._body)})"
            )
        place_objects(m, d, layout)
        # Objects the layout leaves out (another variant's) leave the world.
        self._park([o for o in self.scene.objects if o.name not in layout])
        self.present = tuple(n for n in layout)
        """Names of the objects the layout placed (evaluation only)."""
        if self.controller is not None:
            home = self.robot.home_array()
            d.qpos[self._arm_q] = home
            self.controller.reset(home)
            d.ctrl[self._arm_act] = home
        if self.robot.gripper is not None:
            d.qpos[self._finger_q] = self.robot.gripper.open
            d.ctrl[self._grip_act] = self.robot.gripper.open
        if len(self._base_q):
            d.qpos[self._base_q] = base_pose
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
        object parked under one is thrown out of it (loco_manip's, at 22 m/s)."""
        m, d = self.model, self.data
        x = float(m.stat.center[0])
        parked = []
        for o in objects:
            root = self._body[o.name]
            bodies = [b for b in range(m.nbody) if _descends(m, b, root)]
            geoms = np.flatnonzero(np.isin(m.geom_bodyid, bodies))
            m.geom_contype[geoms] = 0
            m.geom_conaffinity[geoms] = 0
            m.geom_group[geoms] = HIDDEN_GROUP
            radius = float(m.geom_rbound[geoms].max(initial=0.1))
            at = [x + radius, float(m.stat.center[1]), self.park_z]
            x += 2 * radius + PARK_GAP
            if o.name not in self._free_qadr:  # a static body (a poster): move it
                m.body_pos[root], m.body_quat[root] = at, [1, 0, 0, 0]
                continue
            qa, _ = self._free_qadr[o.name]
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

    def step(self, cmd: PoiCommand) -> None:
        """Advance one control period (10 ms) towards ``cmd``.

        An arm's POI target goes through the Cartesian controller; a mobile base's
        ``[x, y, z, yaw]`` (z ignored) is its joints' target directly, the yaw unwrapped to
        the turn nearest the current one (the hinge is continuous).
        """
        if self.mobile_manipulator and cmd.base is None:  # the base holds its last target
            cmd = PoiCommand(cmd.t, cmd.target, cmd.gripper, base=self._last.base)
        self._last = cmd
        target = np.asarray(cmd.target, float)
        if self.controller is not None:
            self.data.ctrl[self._arm_act] = self.controller.update(target)
        if self.robot.gripper is not None:
            self.data.ctrl[self._grip_act] = self.robot.gripper.target(cmd.gripper)
        if len(self._base_act):
            base = (
                np.asarray(cmd.base, float)
                if self.mobile_manipulator and cmd.base is not None
                else np.array([target[0], target[1], target[3]])
            )
            # The target is in odometry's frame: the same place relative to the robot in
            # the joints' frame (identity without drift).
            odom_to_true = compose(self._odom_truth, inverse(self._odom))
            x, y, yaw = compose(odom_to_true, base)
            yaw_now = float(self.data.qpos[self._base_q[2]])
            yaw = yaw_now + wrap(float(yaw) - yaw_now)
            self.data.ctrl[self._base_act] = [x, y, yaw]
        mujoco.mj_step(self.model, self.data, nstep=self.n_substeps)
        if len(self._base_q):
            self._integrate_odometry()

    def _integrate_odometry(self) -> None:
        """Add this period's body-frame motion to odometry, with the drift's error."""
        now = self.data.qpos[self._base_q].astype(float)
        if self.drift is None:
            self._odom, self._odom_truth = now.copy(), now.copy()
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
        if len(self._base_q):
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
        mount = between(self._base_truth(), site)
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
            self._robot = RobotModel.from_mjcf(self.scene.mjcf, js.names)
        return self._robot.geometry_for(js.position)

    # --- camera ------------------------------------------------------------------------

    def render_camera(self) -> CameraFrame:
        """RGB and metric depth (along the optical axis) from the scene's sensor camera."""
        rgb, depth = self._render()
        frame = CameraFrame(
            t=self.t,
            rgb=rgb,
            depth=depth,
            K=self.camera_matrix(),
            T_world_camera=self.camera_pose(),
            frame_id="camera",
        )
        return self.sensor_noise.frame(frame)

    def start_camera(self) -> None:
        """Build the camera's renderer and render one frame, discarded, unless it runs
        already: a GL context's first frames are slow (shaders, buffers), and a decision's
        latency should not include them. Draws no sensor noise, so an episode's readings do
        not depend on whether its simulator is new or reset."""
        if self._renderer is None:
            self._render()

    def _render(self) -> tuple[np.ndarray, np.ndarray]:
        """RGB (h, w, 3) uint8 and depth (h, w) float32 [m], 0 where nothing is seen."""
        cam = self.scene.camera
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, cam.height, cam.width)
            self._renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
            self._renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
        r = self._renderer
        opt = mujoco.MjvOption()
        opt.geomgroup[:] = 1
        opt.geomgroup[HIDDEN_GROUP] = 0  # the teleop marker, parked objects: not the world's
        opt.sitegroup[:] = 0  # sites (the POI marker) are not seen by a real camera
        r.update_scene(self.data, camera=self._cam_id, scene_option=opt)
        rgb = r.render().copy()
        # Depth is a second pass: mujoco.Renderer draws it with segmentation colours, and
        # its depth then differs from the lit pass's by about 1 mm at the table (measured);
        # logs hold the segmented pass's, so replay must perceive the same.
        r.enable_depth_rendering()
        r.update_scene(self.data, camera=self._cam_id, scene_option=opt)
        # mujoco.Renderer already linearises the depth buffer to metres along the optical
        # axis (z-depth, not ray length), which is what CameraFrame wants.
        depth = r.render().astype(np.float32)
        r.disable_depth_rendering()
        far = self.model.vis.map.zfar * self.model.stat.extent
        depth[depth >= 0.999 * far] = 0.0
        return rgb, depth

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
        if len(self._base_q) and self.drift is not None:
            T = planar_se3(self.base_odometry()) @ np.linalg.inv(planar_se3(self._base_truth())) @ T
        return T

    def _base_truth(self) -> np.ndarray:
        """The base body's planar pose from the joints ``[x, y, yaw]`` (what odometry
        integrates; used only to express mountings relative to the base)."""
        d, b = self.data, self._base_body
        return np.array([d.xpos[b][0], d.xpos[b][1], yaw_of(d.xmat[b])])

    def close(self) -> None:
        """Free the renderer's GL context."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # --- evaluation only ---------------------------------------------------------------

    def ground_truth(self) -> dict[str, np.ndarray]:
        """Object poses ``[x, y, z, qw, qx, qy, qz]`` (evaluation only, never for perception)."""
        d = self.data
        return {n: np.concatenate([d.xpos[b], d.xquat[b]]) for n, b in self._body.items()}

    def base_pose(self) -> np.ndarray:
        """The mobile base's true pose ``[x, y, yaw]`` (evaluation only; control reads
        :meth:`poi`, odometry)."""
        q = self.data.qpos[self._base_q]
        return np.array([q[0], q[1], wrap(float(q[2]))])

    def robot_contacts(self) -> list[str]:
        """Names of what the robot's collision geoms touch now, floor excluded (evaluation
        only: a mobile base's collisions; a mobile manipulator's hand is left out)."""
        m, d = self.model, self.data
        mine = set(self._robot_geoms)
        if self.mobile_manipulator:
            # Its hand is meant to touch: the fingers and the body they ride on (the palm)
            # grasp handles and objects; the base and the arm's links must touch nothing.
            fingers = self.robot.gripper.joints if self.robot.gripper else ()
            hand = {int(m.jnt_bodyid[m.joint(j).id]) for j in fingers}
            hand |= {int(m.body_parentid[b]) for b in hand}
            mine = {g for g in mine if int(m.geom_bodyid[g]) not in hand}
        out = []
        for i in range(d.ncon):
            c = d.contact[i]
            g1, g2 = int(c.geom1), int(c.geom2)
            if (g1 in mine) == (g2 in mine):
                continue
            other = g2 if g1 in mine else g1
            if m.geom_type[other] == mujoco.mjtGeom.mjGEOM_PLANE:
                continue
            out.append(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, other) or f"geom {other}")
        return out

    def door_opening(self, joint: str) -> float:
        """A door's joint value now [m or rad] (evaluation only)."""
        return float(
            self.data.qpos[self.model.jnt_qposadr[self._id(mujoco.mjtObj.mjOBJ_JOINT, joint)]]
        )

    def fingers_on(self, geom: str) -> int:
        """How many finger bodies touch ``geom`` now (evaluation only: a handle held)."""
        m, d = self.model, self.data
        g = self._id(mujoco.mjtObj.mjOBJ_GEOM, geom)
        fingers = self.robot.gripper.joints if self.robot.gripper else ()
        bodies = {int(m.jnt_bodyid[m.joint(j).id]) for j in fingers}
        touching = set()
        for i in range(d.ncon):
            c = d.contact[i]
            for a, b in ((c.geom1, c.geom2), (c.geom2, c.geom1)):
                if a == g and int(m.geom_bodyid[b]) in bodies:
                    touching.add(int(m.geom_bodyid[b]))
        return len(touching)

    def has_body(self, name: str) -> bool:
        """Whether the scene's MJCF has a body ``name`` (a door's handle, for the operator)."""
        return mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, name) >= 0

    def object_pose(self, name: str) -> np.ndarray:
        """Object ``[x, y, z, yaw]`` (for the simulated operator and evaluation); also any
        body of the MJCF by name (a handle on a moving door)."""
        b = self._body.get(name)
        if b is None:
            b = self._id(mujoco.mjtObj.mjOBJ_BODY, name)
        return np.array([*self.data.xpos[b], yaw_of(self.data.xmat[b])])

    def push_object(self, name: str, dx: float, dy: float) -> None:
        """Move a free object by ``dx``, ``dy`` [m] on the table and stop it: someone pushed
        it (a disturbance for benchmarks; control learns of it only through the camera)."""
        if name not in self._free_qadr:
            raise ValueError(f"push_object: {name!r} is not a free object of the scene")
        qa, va = self._free_qadr[name]
        self.data.qpos[qa : qa + 2] += (dx, dy)
        self.data.qvel[va : va + 6] = 0.0
        mujoco.mj_forward(self.model, self.data)

    def object_speed(self, name: str) -> float:
        """Linear speed of an object's body [m/s]."""
        if name not in self._free_qadr:
            return 0.0
        _, va = self._free_qadr[name]
        return float(np.linalg.norm(self.data.qvel[va : va + 3]))

    def holds(self, cond: Condition) -> tuple[bool, str]:
        """Whether ``cond`` holds now: the object rests on top of / inside the target, or
        the base stands at the place."""
        if cond.relation == "at":
            gx, gy, gyaw = self.scene.place(cond.target)
            x, y, yaw = self.base_pose()
            dist, dyaw = math.hypot(x - gx, y - gy), abs(wrap(float(yaw - gyaw)))
            ok = dist <= cond.tolerance[0] and dyaw <= cond.tolerance[1]
            return ok, (
                f"base {'at' if ok else 'not at'} {cond.target} ({dist * 100:.1f} cm, "
                f"{math.degrees(dyaw):.1f} deg off)"
            )
        obj, tgt = self.scene.object(cond.object), self.scene.object(cond.target)
        po, pt = self.object_pose(obj.name), self.object_pose(tgt.name)
        # The object's corners (its geoms' bounding boxes) in the target's yawed frame,
        # relative to the target's centre.
        c, s = math.cos(pt[3]), math.sin(pt[3])
        R_t = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        corners = (self._corners(obj.name) - pt[:3]) @ R_t
        t_top, t_bottom = tgt.size[2] / 2, -tgt.size[2] / 2
        still, touching = self._at_rest(obj.name), self._touching(obj.name)
        others = sorted(touching - {tgt.name})
        if cond.relation == "on_top_of":
            # Resting on the top face: the centre over the face, the bottom on it, and held
            # by the target alone (a box hanging over an edge also touches the table). Not
            # the whole footprint: pick_place's cube (diagonal 7.07 cm) overhangs the
            # 7 cm cylinder by a hair when perfectly centred (docs/choices.md).
            lx, ly = (po[:3] - pt[:3]) @ R_t[:, :2]
            over = _in_footprint(tgt, lx, ly, margin=0.0)
            seated = abs(corners[:, 2].min() - t_top) < ON_TOP_TOL
            ok = over and seated and still and touching == {tgt.name}
            why = f"{obj.name} {'on' if ok else 'not resting on'} {tgt.name}"
        else:  # inside: every corner within the inner walls, above the floor
            inner = tgt.wall if tgt.shape == "open_box" else 0.0
            within = all(_in_footprint(tgt, x, y, margin=inner) for x, y in corners[:, :2])
            above = corners[:, 2].min() > t_bottom - INSIDE_TOL
            ok = (
                within
                and above
                and corners[:, 2].min() < t_top
                and still
                and not (touching - {tgt.name})
            )
            why = f"{obj.name} {'inside' if ok else 'not resting inside'} {tgt.name}"
        if not ok:
            detail = [] if still else ["moving"]
            if others:
                detail.append(f"touching {', '.join(others)}")
            if detail:
                why += f" ({'; '.join(detail)})"
        return ok, why

    def _corners(self, name: str) -> np.ndarray:
        """World corners of the bounding boxes of a body's geoms, shape (8 * geoms, 3) [m]."""
        m, d = self.model, self.data
        b = self._body[name]
        signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
        out = []
        for g in np.flatnonzero(m.geom_bodyid == b):
            centre, half = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
            local = centre + signs * half
            out.append(d.geom_xpos[g] + local @ d.geom_xmat[g].reshape(3, 3).T)
        return np.concatenate(out)

    def _at_rest(self, name: str) -> bool:
        """Linear and angular speed under :data:`REST_SPEED` (free objects; fixed: True)."""
        if name not in self._free_qadr:
            return True
        _, va = self._free_qadr[name]
        v = self.data.qvel[va : va + 6]
        return bool(np.linalg.norm(v[:3]) < REST_SPEED[0] and np.linalg.norm(v[3:]) < REST_SPEED[1])

    def _touching(self, name: str) -> set[str]:
        """Names of what touches the object: scene objects and furniture (a body inside
        one, like a scale's platform, counts as it), the robot, else the body's name
        (the table, the floor)."""
        m, d = self.model, self.data
        b = self._body[name]
        robot = {int(m.geom_bodyid[g]) for g in self._robot_geoms}
        owner = {v: k for k, v in self._body.items()}
        out = set()
        for i in range(d.ncon):
            con = d.contact[i]
            b1, b2 = int(m.geom_bodyid[con.geom1]), int(m.geom_bodyid[con.geom2])
            if b not in (b1, b2):
                continue
            other = b2 if b1 == b else b1
            if other in robot:
                out.add("robot")
                continue
            while other not in owner and m.body_parentid[other] != 0:
                other = int(m.body_parentid[other])
            out.add(
                owner.get(other) or mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, other) or "world"
            )
        return out

    def success(self, task: str | None = None) -> Success:
        """The scene's success criterion for ``task`` (default: any task succeeds)."""
        crits = [c for c in self.scene.success if task is None or c.task == task]
        if task is None:  # only the criteria of the variant on show
            crits = [c for c in crits if c.variant is None or self.shows(c.variant)]
            if not crits:
                return Success(False, "no task's criterion applies to this layout")
        if not crits:
            valid = ", ".join(c.task for c in self.scene.success)
            raise SceneError(f"scene {self.scene.name}: no task {task!r} (tasks: {valid})")
        reasons, details = [], []
        for crit in crits:
            ok, results = self._holds_group(crit.rule)
            details += [(crit.task, text, held) for text, held, _ in results]
            if ok:
                # What made it hold: every all_of condition, the first any_of one that held.
                shown = _explain(results, True)
                return Success(True, f"{crit.task}: {'; '.join(shown)}", tuple(details))
            reasons.append(f"{crit.task}: " + "; ".join(_explain(results, False)))
        return Success(False, " | ".join(reasons), tuple(details))

    def _holds_group(self, group: Group) -> tuple[bool, list[tuple[str, bool, str]]]:
        """Whether ``group`` holds, and each of its conditions' (text, held, the kind of
        the group right above it), in file order."""
        oks, results = [], []
        for item in group.items:
            if isinstance(item, Group):
                ok, inner = self._holds_group(item)
            else:
                held, text = self.holds(item)
                ok = bool(held)  # numpy's bool from a comparison is no JSON boolean
                inner = [(text, ok, group.kind)]
            oks.append(ok)
            results += inner
        if group.kind == "all_of":
            return all(oks), results
        if group.kind == "any_of":
            return any(oks), results
        return not any(oks), results

    def shows(self, variant: str) -> bool:
        """Whether the layout shows every object of ``variant``."""
        return set(dict(self.scene.variants)[variant]) <= set(self.present)


@dataclass(frozen=True, slots=True)
class Push:
    """Someone moves an object while the robot works (:meth:`Sim.push_object`): a
    disturbance for benchmarks and tests, never seen by control but through the camera."""

    object: str
    """The free object moved."""
    at: float
    """Simulation time of the push [s]."""
    dx: float
    """Displacement along world x [m]."""
    dy: float
    """Displacement along world y [m]."""


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


def _with_target_marker(scene: Scene) -> mujoco.MjModel:
    """The scene's model plus the teleop target marker: a mocap body :data:`MARKER_BODY`
    with one small sphere in geom group :data:`HIDDEN_GROUP` that collides with nothing.

    MuJoCo's viewer lets a person select a body (double-click) and move a mocap body with
    Ctrl + right drag (rotate: Ctrl + left drag), which is how the paper's interactive
    marker is dragged. A mocap body has no degrees of freedom and the geom no contacts, so
    the physics is the scene's to the bit (``tests/test_keyboard.py`` checks it); the
    sensor camera and the lidar leave the marker's group out.
    """
    spec = mujoco.MjSpec.from_string(scene.mjcf)
    body = spec.worldbody.add_body(name=MARKER_BODY, mocap=True)
    body.add_geom(
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[MARKER_RADIUS, 0, 0],
        rgba=[1.0, 0.1, 0.9, 0.7],
        group=HIDDEN_GROUP,
        contype=0,
        conaffinity=0,
        mass=0.0,
    )
    return spec.compile()


def _in_footprint(tgt: ObjectSpec, lx: float, ly: float, margin: float) -> bool:
    if tgt.shape == "cylinder":
        return math.hypot(lx, ly) < tgt.size[0] / 2 - margin
    return abs(lx) < tgt.size[0] / 2 - margin and abs(ly) < tgt.size[1] / 2 - margin


def _explain(results: list[tuple[str, bool, str]], ok: bool) -> list[str]:
    """The conditions that say why a criterion held (``ok``: every one under an all_of,
    the first that held under an any_of) or failed (a none_of condition that held; else
    every one that did not)."""
    if ok:
        shown = [t for t, held, kind in results if held and kind == "all_of"]
        first = next((t for t, held, kind in results if held and kind == "any_of"), None)
        return shown + ([first] if first else [])
    bad = [t for t, held, kind in results if held and kind == "none_of"]
    if bad:
        return bad
    return [t for t, held, kind in results if kind != "none_of" and not held] or [
        t for t, _, _ in results
    ]
