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

from smccli.world.objects import add_object  # noqa: E402
from smccli.world.scene import ObjectSpec as SceneObject  # noqa: E402
from smccli.world.sensors import CameraFrame, RobotGeometry  # noqa: E402

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


def _built(name: str, shape: str, size: tuple[float, float, float], rgba: tuple) -> SceneObject:
    return SceneObject(
        name=name,
        shape=shape,
        size=size,
        rgba=rgba,
        mass=0.1,
        pose=(*PARK, 0.0),
        range_x=(PARK[0], PARK[0]),
        range_y=(PARK[1], PARK[1]),
        range_yaw=(0.0, 0.0),
    )


MUG = _built("white_mug", "mug", (0.09, 0.06, 0.08), WHITE)
"""A white mug (body 6 cm across, 8 cm tall, handle reaching 3 cm out on its +x side): the
body is the white cylinder's, so only the handle tells them apart."""
BUILT: tuple[SceneObject, ...] = (
    MUG,
    _built("grey_step_pyramid", "pyramid", (0.06, 0.06, 0.06), GREY),
    _built("white_long_box", "box", (0.14, 0.04, 0.05), WHITE),
    _built("orange_open_box", "open_box", (0.26, 0.16, 0.07), (1.0, 0.45, 0.05, 1.0)),
    _built("grey_bin", "open_box", (0.18, 0.18, 0.08), GREY),
    _built("scale", "scale", (0.14, 0.14, 0.04), (0.7, 0.7, 0.72, 1.0)),
)
"""Objects built by :mod:`smccli.world.objects` itself (``add_object``, the geometry of the
built-in scenes): the mug, the stepped pyramid, the bins, the scale. They have free joints
and are placed through ``qpos``; they are not part of :data:`OBJECTS`, so the separability
figures keep their meaning."""


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
        spec = mujoco.MjSpec.from_string(scene_xml())
        for obj in BUILT:
            add_object(spec, obj)
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        self.renderer = mujoco.Renderer(self.model, height=HEIGHT, width=WIDTH)
        self.renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
        self.camera = self.model.camera("rgbd").id
        self._mocap = {s.name: self.model.body(s.name).mocapid[0] for s in OBJECTS}
        self._mocap["arm"] = self.model.body("arm").mocapid[0]
        self._qpos = {o.name: self.model.joint(f"{o.name}_joint").qposadr[0] for o in BUILT}
        self.arm_in_view = False
        self.clear()

    def close(self) -> None:
        self.renderer.close()

    def clear(self) -> None:
        """Park every object and the arm out of view."""
        for i, name in enumerate(self._mocap):
            self.data.mocap_pos[self._mocap[name]] = PARK + [0.0, 0.3 * i, 0.0]
            self.data.mocap_quat[self._mocap[name]] = [1, 0, 0, 0]
        for i, name in enumerate(self._qpos):
            a = self._qpos[name]
            self.data.qpos[a : a + 7] = [*(PARK + [0.5, 0.3 * i, 0.0]), 1, 0, 0, 0]
        self.arm_in_view = False

    def place(self, name: str, x: float, y: float, yaw: float) -> np.ndarray:
        """Put an object upright on the table; returns its true box centre, shape (3,) [m]."""
        center = np.array([x, y, TABLE_TOP + size_of(name)[2] / 2])
        quat = [np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]
        if name in self._qpos:
            a = self._qpos[name]
            self.data.qpos[a : a + 7] = [*center, *quat]
        else:
            self.data.mocap_pos[self._mocap[name]] = center
            self.data.mocap_quat[self._mocap[name]] = quat
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


def size_of(name: str) -> tuple[float, float, float]:
    """Full extents of a test object, :data:`OBJECTS` or :data:`BUILT` [m]."""
    for obj in BUILT:
        if obj.name == name:
            return obj.size
    return spec_by_name(name).size


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


def handle_hidden(x: float, y: float, yaw: float, cone: float = np.pi / 6) -> bool:
    """Whether a mug at ``(x, y, yaw)`` has its handle pointing within ``cone`` [rad] of
    straight away from the camera (ground truth, for tests: then the body may hide it)."""
    away = np.arctan2(y - CAMERA_POS[1], x - CAMERA_POS[0])
    return abs((yaw - away + np.pi) % (2 * np.pi) - np.pi) < cone


def symmetry(n_poses: int = 100, seed: int = 0, n_clutter: int = 50) -> dict:
    """How often objects are seen as having no symmetry (``yaw_period`` 2 pi).

    Renders each object of :data:`OBJECTS` and :data:`BUILT` alone at ``n_poses`` random
    poses: the mug should be asymmetric with its yaw at the handle, the others never. Then
    ``n_clutter`` frames of six random small objects (the mug among them) with the arm in
    view. Also d_cluster within the mug's views (handle seen or not) and against the white
    cylinder (the mug's body without a handle).
    """
    from smccli.perception import PerceptionParams, clusters_from_frame, d_cluster

    params = PerceptionParams(**CROP)
    rng = np.random.default_rng(seed)
    scene = PerceptionScene()
    names = [s.name for s in OBJECTS] + [o.name for o in BUILT]
    asymmetric = {n: 0 for n in names}
    miscounted = {n: 0 for n in names}
    yaw_err, mug_views, mug_asym, cylinders, centre_err = [], [], [], [], []
    hidden = {"poses": 0, "asymmetric": 0}
    try:
        for name in names:
            for _ in range(n_poses):
                scene.clear()
                x, y, yaw = random_pose(rng)
                center = scene.place(name, x, y, yaw)
                found = clusters_from_frame(scene.render(), None, params)
                if len(found) != 1:
                    miscounted[name] += 1
                    continue
                (c,) = found
                asym = c.yaw_period > 2 * np.pi - 1e-6
                asymmetric[name] += asym
                if name == "white_cylinder":
                    cylinders.append(c)
                if name != MUG.name:
                    continue
                mug_views.append(c)
                mug_asym.append(asym)
                if handle_hidden(x, y, yaw):
                    hidden["poses"] += 1
                    hidden["asymmetric"] += asym
                err = (c.yaw - yaw + np.pi) % (2 * np.pi) - np.pi
                yaw_err.append(np.degrees(abs(err)) if asym else np.inf)
                if asym:
                    centre_err.append(float(np.linalg.norm(c.centroid - center)))
        clutter_names = [s.name for s in OBJECTS] + [MUG.name, "grey_step_pyramid"]
        # Each layout without the arm (every object must be found once) and with it (it
        # hides objects and parts of their tops: none may look asymmetric but the mug).
        clutter = {"frames": n_clutter, "with_mug": 0, "miscounted_without_arm": 0}
        for arm in ("without_arm", "with_arm"):
            clutter |= {f"mug_asymmetric_{arm}": 0, f"other_asymmetric_{arm}": 0}
        for _ in range(n_clutter):
            scene.clear()
            picks = list(rng.choice(clutter_names, size=6, replace=False))
            truth = {n: scene.place(n, *p) for n, p in random_layout(rng, picks, 0.16).items()}
            clutter["with_mug"] += MUG.name in picks
            for arm in ("without_arm", "with_arm"):
                if arm == "with_arm":
                    scene.show_arm()
                found = clusters_from_frame(scene.render(), scene.robot_geometry(), params)
                if arm == "without_arm":
                    clutter["miscounted_without_arm"] += len(found) != len(picks)
                for c in found:
                    near = min(truth, key=lambda n: np.hypot(*(truth[n][:2] - c.centroid[:2])))
                    if c.yaw_period > 2 * np.pi - 1e-6:
                        who = "mug" if near == MUG.name else "other"
                        clutter[f"{who}_asymmetric_{arm}"] += 1
    finally:
        scene.close()
    err = np.array(yaw_err)
    seen = err[np.isfinite(err)]
    flags = np.array(mug_asym, dtype=bool)
    seen_extents = [c.extents for c, f in zip(mug_views, flags, strict=True) if f]
    mixed = [
        d_cluster(a, b, params)
        for i, a in enumerate(mug_views)
        for j, b in enumerate(mug_views)
        if flags[i] and not flags[j]
    ]
    same_kind = [
        d_cluster(mug_views[i], mug_views[j], params)
        for i, j in itertools.combinations(np.flatnonzero(flags), 2)
    ]
    vs_cyl = [
        d_cluster(m, c, params)
        for m, f in zip(mug_views, flags, strict=True)
        for c in cylinders
        if f
    ]
    round_vs_cyl = [
        d_cluster(m, c, params)
        for m, f in zip(mug_views, flags, strict=True)
        for c in cylinders
        if not f
    ]

    def stats(v: list[float]) -> dict:
        return {"n": len(v), "min": min(v), "max": max(v)} if v else {"n": 0}

    return {
        "n_poses": n_poses,
        "seed": seed,
        "asymmetric": asymmetric,
        "miscounted": miscounted,
        "mug_asymmetric_yaw_within_10deg": int((err < 10).sum()),
        "mug_yaw_err_deg": {"median": float(np.median(seen)), "max": float(seen.max())}
        if len(seen)
        else {},
        "mug_handle_within_30deg_of_away": hidden,
        "mug_centre_err_cm_max": 100 * max(centre_err, default=np.nan),
        "mug_asymmetric_extents_cm": {
            "min": (100 * np.min(seen_extents, axis=0)).round(1).tolist(),
            "max": (100 * np.max(seen_extents, axis=0)).round(1).tolist(),
        }
        if len(seen_extents)
        else {},
        "clutter": clutter,
        "d_mug_views_both_asymmetric": stats(same_kind),
        "d_mug_asymmetric_vs_round_view": stats(mixed),
        "d_mug_asymmetric_vs_white_cylinder": stats(vs_cyl),
        "d_mug_round_view_vs_white_cylinder": stats(round_vs_cyl),
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

    if sys.argv[1:2] == ["symmetry"]:
        # MUJOCO_GL=egl .venv/bin/python -m tests.perception_scene symmetry [n_poses] [seed]
        n = int(sys.argv[2]) if len(sys.argv) > 2 else 100
        seed = int(sys.argv[3]) if len(sys.argv) > 3 else 0
        print(json.dumps(symmetry(n, seed), indent=1))
        sys.exit()
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 100
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 0
    print(json.dumps({"timing": timing(50, seed), "separability": separability(n, seed)}, indent=1))
