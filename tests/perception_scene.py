"""A tiny inline MuJoCo scene for the perception tests and the separability benchmark.

A table, a fixed RGB-D camera above the robot's side looking forward and down at it, the
objects of the built-in scenes (white box, white cylinder, grey pyramid, grey box, orange
cube, green and yellow cylinders, two blue boxes) as mocap bodies that can be put anywhere,
and a crude arm stand-in (capsules) with the :class:`RobotGeometry` that describes it.

Ground truth (object poses) is used only in the tests' assertions and to place objects;
the pipeline under test sees only the :class:`CameraFrame`.
"""

from __future__ import annotations

import itertools
import json
import os
import time
from dataclasses import dataclass

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering unless told otherwise

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from smccli.sensors import CameraFrame, RobotGeometry  # noqa: E402

TABLE_TOP = 0.75
"""Height of the table top [m]."""
CROP = dict(crop_min=(0.1, -0.7, 0.6), crop_max=(1.2, 0.7, 1.4))
"""Workspace box of this scene (its table is higher than the built-in scenes')."""
TABLE_CENTER = (0.55, 0.0)
TABLE_HALF = (0.35, 0.5)
CAMERA_POS = np.array([0.0, 0.0, 1.35])
CAMERA_TARGET = np.array([0.55, 0.0, TABLE_TOP])
FOVY_DEG = 58.0
WIDTH, HEIGHT = 320, 240
PLACE_X = (0.33, 0.78)
"""Range of object x positions in view [m]."""
PLACE_Y = (-0.3, 0.3)
"""Range of object y positions in view [m]."""
PARK = np.array([3.0, 3.0, 0.0])
"""Where unused objects and the arm are parked (out of the crop box) [m]."""

ARM_TOP = np.array([0.50, 0.18, 1.25])
"""Upper end of the arm stand-in's hanging link when it is in view [m]."""
ARM_LEN = 0.40
ARM_RADIUS = 0.03


@dataclass(frozen=True, slots=True)
class ObjectSpec:
    """One test object; its body origin is the centre of its bounding box."""

    name: str
    kind: str
    """``"box"``, ``"cylinder"`` or ``"pyramid"``."""
    size: tuple[float, float, float]
    """Full extents (length along body x, width along body y, height) [m]."""
    rgba: tuple[float, float, float, float]

    @property
    def yaw_period(self) -> float:
        """Footprint symmetry [rad]: pi elongated, pi/2 square, 0 round."""
        if self.kind == "cylinder":
            return 0.0
        return np.pi / 2 if abs(self.size[0] - self.size[1]) < 1e-9 else np.pi


WHITE = (0.92, 0.92, 0.92, 1.0)
GREY = (0.5, 0.5, 0.5, 1.0)
OBJECTS: tuple[ObjectSpec, ...] = (
    ObjectSpec("white_box", "box", (0.09, 0.06, 0.05), WHITE),
    ObjectSpec("white_cylinder", "cylinder", (0.06, 0.06, 0.08), WHITE),
    ObjectSpec("grey_pyramid", "pyramid", (0.06, 0.06, 0.06), GREY),
    ObjectSpec("grey_box", "box", (0.07, 0.04, 0.03), GREY),
    ObjectSpec("orange_cube", "box", (0.05, 0.05, 0.05), (1.0, 0.5, 0.05, 1.0)),
    ObjectSpec("green_cylinder", "cylinder", (0.07, 0.07, 0.06), (0.1, 0.7, 0.2, 1.0)),
    ObjectSpec("yellow_cylinder", "cylinder", (0.07, 0.07, 0.06), (0.95, 0.85, 0.1, 1.0)),
    ObjectSpec("blue_box", "box", (0.10, 0.05, 0.04), (0.1, 0.25, 0.85, 1.0)),
    ObjectSpec("blue_box_small", "box", (0.06, 0.04, 0.03), (0.1, 0.25, 0.85, 1.0)),
)


def _camera_xyaxes() -> str:
    # MuJoCo cameras look along their -z with y up: x = right, y = up.
    forward = CAMERA_TARGET - CAMERA_POS
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    return " ".join(f"{v:.6f}" for v in (*right, *up))


def _geom_xml(spec: ObjectSpec) -> str:
    rgba = " ".join(str(c) for c in spec.rgba)
    lx, ly, h = (s / 2 for s in spec.size)
    if spec.kind == "box":
        return f'<geom type="box" size="{lx} {ly} {h}" rgba="{rgba}"/>'
    if spec.kind == "cylinder":
        return f'<geom type="cylinder" size="{lx} {h}" rgba="{rgba}"/>'
    return f'<geom type="mesh" mesh="{spec.name}_mesh" rgba="{rgba}"/>'


def scene_xml() -> str:
    """The MJCF of the test scene."""
    meshes = []
    for spec in OBJECTS:
        if spec.kind == "pyramid":
            lx, ly, h = (s / 2 for s in spec.size)
            verts = f"{-lx} {-ly} {-h}  {lx} {-ly} {-h}  {lx} {ly} {-h}  {-lx} {ly} {-h}  0 0 {h}"
            meshes.append(f'<mesh name="{spec.name}_mesh" vertex="{verts}"/>')
    bodies = "\n".join(
        f'<body name="{s.name}" mocap="true" pos="{PARK[0]} {PARK[1] + i} 0">{_geom_xml(s)}</body>'
        for i, s in enumerate(OBJECTS)
    )
    tx, ty = TABLE_CENTER
    hx, hy = TABLE_HALF
    return f"""
<mujoco model="perception_test">
  <visual><global offwidth="{WIDTH}" offheight="{HEIGHT}"/><quality shadowsize="0"/></visual>
  <asset>{"".join(meshes)}</asset>
  <worldbody>
    <light directional="true" pos="0 0 3" dir="0.2 0.1 -1" diffuse="0.6 0.6 0.6"/>
    <geom type="plane" size="3 3 0.1" rgba="0.3 0.3 0.35 1"/>
    <geom name="table" type="box" pos="{tx} {ty} {TABLE_TOP / 2}" size="{hx} {hy} {TABLE_TOP / 2}"
          rgba="0.55 0.42 0.3 1"/>
    <camera name="rgbd" pos="{" ".join(map(str, CAMERA_POS))}" xyaxes="{_camera_xyaxes()}"
            fovy="{FOVY_DEG}"/>
    {bodies}
    <body name="arm" mocap="true" pos="{PARK[0]} {-PARK[1]} {PARK[2]}">
      <geom type="capsule" fromto="0 0 0  0 0 {-ARM_LEN}" size="{ARM_RADIUS}"
            rgba="0.2 0.2 0.22 1"/>
      <geom type="capsule" fromto="0 0 {-ARM_LEN}  0.08 0 {-ARM_LEN - 0.04}" size="0.02"
            rgba="0.2 0.2 0.22 1"/>
    </body>
  </worldbody>
</mujoco>
"""


class PerceptionScene:
    """The test scene with a renderer: place objects, render a :class:`CameraFrame`."""

    def __init__(self) -> None:
        self.model = mujoco.MjModel.from_xml_string(scene_xml())
        self.data = mujoco.MjData(self.model)
        self.renderer = mujoco.Renderer(self.model, height=HEIGHT, width=WIDTH)
        self.renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
        self.camera = self.model.camera("rgbd").id
        self._mocap = {s.name: self.model.body(s.name).mocapid[0] for s in OBJECTS}
        self._mocap["arm"] = self.model.body("arm").mocapid[0]
        self.arm_in_view = False
        self.clear()

    def close(self) -> None:
        self.renderer.close()

    def clear(self) -> None:
        """Park every object and the arm out of view."""
        for i, name in enumerate(self._mocap):
            self.data.mocap_pos[self._mocap[name]] = PARK + [0.0, 0.3 * i, 0.0]
            self.data.mocap_quat[self._mocap[name]] = [1, 0, 0, 0]
        self.arm_in_view = False

    def place(self, name: str, x: float, y: float, yaw: float) -> np.ndarray:
        """Put an object upright on the table; returns its true box centre, shape (3,) [m]."""
        spec = spec_by_name(name)
        center = np.array([x, y, TABLE_TOP + spec.size[2] / 2])
        self.data.mocap_pos[self._mocap[name]] = center
        self.data.mocap_quat[self._mocap[name]] = [np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]
        return center

    def show_arm(self, top: np.ndarray = ARM_TOP) -> None:
        """Hang the arm stand-in's link into the view from ``top``."""
        self.data.mocap_pos[self._mocap["arm"]] = top
        self.data.mocap_quat[self._mocap["arm"]] = [1, 0, 0, 0]
        self.arm_in_view = True

    def robot_geometry(self, margin: float = 0.01) -> RobotGeometry:
        """Bounding spheres of the arm stand-in (what a robot knows from its own kinematics)."""
        if not self.arm_in_view:
            return RobotGeometry()
        top = self.data.mocap_pos[self._mocap["arm"]].copy()
        end = top + [0.0, 0.0, -ARM_LEN]
        tip = end + [0.08, 0.0, -0.04]
        link = np.linspace(top, end, 15)
        finger = np.linspace(end, tip, 5)
        centers = np.vstack([link, finger])
        radii = np.r_[np.full(len(link), ARM_RADIUS), np.full(len(finger), 0.02)] + margin
        return RobotGeometry(centers=centers, radii=radii)

    def render(self, t: float = 0.0) -> CameraFrame:
        """Render colour and depth from the fixed camera."""
        mujoco.mj_forward(self.model, self.data)
        self.renderer.update_scene(self.data, camera=self.camera)
        rgb = self.renderer.render().copy()
        self.renderer.enable_depth_rendering()
        self.renderer.update_scene(self.data, camera=self.camera)
        depth = self.renderer.render().astype(np.float32)
        self.renderer.disable_depth_rendering()
        f = HEIGHT / 2 / np.tan(np.deg2rad(FOVY_DEG) / 2)
        # Pixel (u, v) integer indices: the ray through a pixel's centre is at u + 0.5.
        K = np.array([[f, 0, WIDTH / 2 - 0.5], [0, f, HEIGHT / 2 - 0.5], [0, 0, 1]])
        T = np.eye(4)
        T[:3, 3] = self.data.cam_xpos[self.camera]
        # MuJoCo camera: x right, y up, looks along -z; optical: x right, y down, z forward.
        T[:3, :3] = self.data.cam_xmat[self.camera].reshape(3, 3) @ np.diag([1.0, -1.0, -1.0])
        return CameraFrame(t=t, rgb=rgb, depth=depth, K=K, T_world_camera=T)


def spec_by_name(name: str) -> ObjectSpec:
    for spec in OBJECTS:
        if spec.name == name:
            return spec
    raise KeyError(f"unknown test object {name!r}; valid: {[s.name for s in OBJECTS]}")


def random_pose(rng: np.random.Generator) -> tuple[float, float, float]:
    """A uniformly random (x, y, yaw) in view [m, m, rad]."""
    return (rng.uniform(*PLACE_X), rng.uniform(*PLACE_Y), rng.uniform(-np.pi, np.pi))


def random_layout(
    rng: np.random.Generator, names: list[str], min_gap: float = 0.14
) -> dict[str, tuple[float, float, float]]:
    """Non-overlapping random poses for several objects (rejection sampling)."""
    while True:
        poses = {n: random_pose(rng) for n in names}
        xy = np.array([p[:2] for p in poses.values()])
        gaps = [np.linalg.norm(a - b) for a, b in itertools.combinations(xy, 2)]
        if not gaps or min(gaps) > min_gap:
            return poses


def separability(n_poses: int = 100, seed: int = 0) -> dict:
    """Render each object alone at ``n_poses`` random poses and compare clusters.

    Returns the within-object distances (same object, all pose pairs; must stay below
    T_hP = 0.1) and the between-object distances (all pairs of poses of different
    objects; must stay above it), with their 99th and 1st percentiles, the worst pairs,
    and the mean time of ``clusters_from_frame`` [ms].
    """
    from smccli.perception import PerceptionParams, clusters_from_frame, d_cluster

    params = PerceptionParams(**CROP)
    rng = np.random.default_rng(seed)
    scene = PerceptionScene()
    clusters: dict[str, list] = {s.name: [] for s in OBJECTS}
    missed: dict[str, int] = {s.name: 0 for s in OBJECTS}
    times = []
    try:
        for spec in OBJECTS:
            for _ in range(n_poses):
                scene.clear()
                scene.place(spec.name, *random_pose(rng))
                frame = scene.render()
                t0 = time.perf_counter()
                found = clusters_from_frame(frame, None, params)
                times.append(time.perf_counter() - t0)
                if len(found) == 1:
                    clusters[spec.name].append(found[0])
                else:
                    missed[spec.name] += 1
    finally:
        scene.close()
    within: dict[str, np.ndarray] = {}
    for name, cs in clusters.items():
        within[name] = np.array([d_cluster(a, b, params) for a, b in itertools.combinations(cs, 2)])
    between: dict[tuple[str, str], np.ndarray] = {}
    for na, nb in itertools.combinations(clusters, 2):
        between[(na, nb)] = np.array(
            [d_cluster(a, b, params) for a in clusters[na] for b in clusters[nb]]
        )
    w_all = np.concatenate(list(within.values()))
    b_all = np.concatenate(list(between.values()))
    return {
        "n_poses": n_poses,
        "seed": seed,
        "missed": missed,
        "within_p99": float(np.percentile(w_all, 99)),
        "within_max": float(w_all.max()),
        "between_p1": float(np.percentile(b_all, 1)),
        "between_min": float(b_all.min()),
        "within_p99_by_object": {n: float(np.percentile(v, 99)) for n, v in within.items()},
        "between_min_by_pair": {f"{a}/{b}": float(v.min()) for (a, b), v in between.items()},
        "ms_per_frame": 1e3 * float(np.mean(times)),
    }


def timing(n_frames: int = 50, seed: int = 0) -> dict:
    """Time ``clusters_from_frame`` on cluttered frames: six objects and the arm in view.

    Returns the median, 95th percentile and minimum [ms], the mean number of clusters
    found, and the machine's load average (other processes inflate wall times).
    """
    from smccli.perception import PerceptionParams, clusters_from_frame

    params = PerceptionParams(**CROP)
    rng = np.random.default_rng(seed)
    scene = PerceptionScene()
    times, counts = [], []
    try:
        for _ in range(n_frames):
            scene.clear()
            names = list(rng.choice([s.name for s in OBJECTS], size=6, replace=False))
            for name, pose in random_layout(rng, names).items():
                scene.place(name, *pose)
            scene.show_arm()
            frame, robot = scene.render(), scene.robot_geometry()
            clusters_from_frame(frame, robot, params)  # warm caches, then time
            t0 = time.perf_counter()
            found = clusters_from_frame(frame, robot, params)
            times.append(time.perf_counter() - t0)
            counts.append(len(found))
    finally:
        scene.close()
    ms = 1e3 * np.array(times)
    return {
        "n_frames": n_frames,
        "image": f"{WIDTH}x{HEIGHT}",
        "ms_median": float(np.median(ms)),
        "ms_p95": float(np.percentile(ms, 95)),
        "ms_min": float(ms.min()),
        "load_average_1min": os.getloadavg()[0],
        "clusters_mean": float(np.mean(counts)),
    }


if __name__ == "__main__":
    # MUJOCO_GL=egl .venv/bin/python tests/perception_scene.py [n_poses] [seed]
    import sys

    n = int(sys.argv[1]) if len(sys.argv) > 1 else 100
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 0
    print(json.dumps({"timing": timing(50, seed), "separability": separability(n, seed)}, indent=1))
