"""Layouts: where a scene's objects, furniture and a mobile robot's start are in one episode.

A layout maps object (or furniture) name -> ``[x, y, z, yaw]`` [m, m, m, rad], and
:data:`~smccli.world.scene.ROBOT_KEY` -> a mobile base's start. :func:`sample_layout` draws
one from the scene's ranges (objects apart, a start that touches nothing);
:func:`load_layout_file` reads a user's; :func:`nominal_layout` is the scene file's own.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np

from smccli.errors import SceneError
from smccli.schemas import check_yaml, parse_yaml
from smccli.world.geometry import yaw_quat
from smccli.world.robot import robot_geoms
from smccli.world.scene import ROBOT_KEY, Layout, Scene


def nominal_layout(scene: Scene, variant: str | None = None) -> Layout:
    """The objects of ``variant`` (default: all) at their nominal poses."""
    present = scene.variant_objects(variant)
    layout: Layout = {o.name: tuple(o.pose) for o in scene.objects if o.name in present}  # type: ignore[misc]
    for f in scene.furniture:
        layout[f.name] = f.pose
    if scene.start is not None:
        x, y, yaw = scene.start.pose
        layout[ROBOT_KEY] = (x, y, 0.0, yaw)
    return layout


def sample_layout(
    scene: Scene, rng: np.random.Generator, *, variant: str | None = None, max_tries: int = 1000
) -> Layout:
    """Draw each object's x, y, yaw uniformly from its ranges; redraw while footprints overlap.

    A scene with variants draws one uniformly unless ``variant`` is given. Footprints are
    the circles circumscribing the objects (conservative), with 1 cm between. A mobile
    robot's start is drawn again while it collides (:func:`start_collisions`); SceneError
    when ``max_tries`` draws give no free layout.
    """
    gap = 0.01
    if variant is None and scene.variants:
        names = [v for v, _ in scene.variants]
        variant = names[int(rng.integers(len(names)))]
    present = scene.variant_objects(variant)
    blocked: set[str] = set()
    for _ in range(max_tries):
        layout: Layout = {}
        moved: dict[str, tuple[float, float, float, float]] = {}
        for f in scene.furniture:
            fx, fy, fyaw = _draw(rng, f.range_x, f.range_y, f.range_yaw)
            layout[f.name] = (fx, fy, f.pose[2], fyaw)
            moved[f.name] = f.pose
        for o in scene.objects:
            if o.name not in present:
                continue
            x, y, yaw = _draw(rng, o.range_x, o.range_y, o.range_yaw)
            if o.on is not None:  # drawn at the furniture's nominal pose, moved with it
                x, y, yaw = _carry(moved[o.on], layout[o.on], (x, y, yaw))
            layout[o.name] = (x, y, o.pose[2], yaw)
        if scene.start is not None:
            st = scene.start
            x, y, yaw = _draw(rng, st.range_x, st.range_y, st.range_yaw)
            layout[ROBOT_KEY] = (x, y, 0.0, yaw)
        if _overlaps(scene, layout, gap):
            continue
        # A start inside a wall or a piece of furniture is drawn again: the episode would
        # only fail as a collision, which says nothing about the tree.
        hit = start_collisions(scene, layout) if scene.start is not None else []
        if not hit:
            return layout
        blocked.update(hit)
    if blocked:
        raise SceneError(
            f"{scene.yaml_path or scene.name}: start.range leaves the robot no room: every start "
            f"of {max_tries} drawn collides (with {', '.join(sorted(blocked))}); move or "
            "narrow the start's ranges"
        )
    raise SceneError(
        f"scene {scene.name}: no overlap-free layout in {max_tries} draws (ranges too tight)"
    )


_CHECKERS: dict[str, tuple[mujoco.MjModel, mujoco.MjData, threading.Lock]] = {}


def start_collisions(scene: Scene, layout: Layout) -> list[str]:
    """Names of what the robot's collision geoms penetrate at the layout's start: the base
    at :data:`ROBOT_KEY`, an arm at home, furniture and objects where the layout puts them
    (floor planes left out). Empty when the start is free."""
    robot = scene.robot
    if scene.digest not in _CHECKERS:
        model = scene.model()
        _CHECKERS[scene.digest] = (model, mujoco.MjData(model), threading.Lock())
    m, d, lock = _CHECKERS[scene.digest]
    with lock:  # one model per scene, shared by a Dask worker's threads
        pos0, quat0 = m.body_pos.copy(), m.body_quat.copy()
        try:
            mujoco.mj_resetData(m, d)
            place_objects(m, d, {k: v for k, v in layout.items() if k != ROBOT_KEY})
            if robot.base is not None and ROBOT_KEY in layout:
                x, y, _, yaw = layout[ROBOT_KEY]
                for j, q in zip(robot.base.joints, (x, y, yaw), strict=True):
                    d.qpos[m.jnt_qposadr[m.joint(j).id]] = q
            for j, q in zip(robot.arm_joints, robot.home_array(), strict=True):
                d.qpos[m.jnt_qposadr[m.joint(j).id]] = q
            mujoco.mj_forward(m, d)
            mine = set(robot_geoms(robot, m).tolist())
            hit = set()
            for c in d.contact[: d.ncon]:
                g1, g2 = int(c.geom1), int(c.geom2)
                if (g1 in mine) == (g2 in mine) or c.dist >= 0:
                    continue
                other = g2 if g1 in mine else g1
                if m.geom_type[other] == mujoco.mjtGeom.mjGEOM_PLANE:
                    continue
                body = int(m.body_rootid[m.geom_bodyid[other]])
                name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, other)
                hit.add(name or mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, body) or "world")
            return sorted(hit)
        finally:
            m.body_pos[:], m.body_quat[:] = pos0, quat0


def place_objects(m: mujoco.MjModel, d: mujoco.MjData, layout: Layout) -> None:
    """Put each object of ``layout`` (name -> ``[x, y, z, yaw]``, no robot key) where it
    says: a free body by its joint, a static one (a scale, a fixed bin) by its body's own
    pose in the model."""
    for name, (x, y, z, yaw) in layout.items():
        b = m.body(name).id
        quat = yaw_quat(yaw)
        j = m.body_jntadr[b]
        if j >= 0 and m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            qa = m.jnt_qposadr[j]
            d.qpos[qa : qa + 7] = [x, y, z, *quat]
        else:
            m.body_pos[b], m.body_quat[b] = [x, y, z], quat


def _draw(
    rng: np.random.Generator,
    rx: tuple[float, float],
    ry: tuple[float, float],
    ryaw: tuple[float, float],
) -> tuple[float, float, float]:
    """x, y, yaw drawn uniformly from their ranges (equal bounds: that value)."""
    return tuple(  # type: ignore[return-value]
        float(rng.uniform(lo, hi)) if lo < hi else lo for lo, hi in (rx, ry, ryaw)
    )


def _carry(
    nominal: Sequence[float], actual: Sequence[float], pose: tuple[float, float, float]
) -> tuple[float, float, float]:
    """A pose ``(x, y, yaw)`` given with furniture at ``nominal`` (x, y, z, yaw), moved
    with it to ``actual``."""
    dyaw = actual[3] - nominal[3]
    c, s = math.cos(dyaw), math.sin(dyaw)
    dx, dy = pose[0] - nominal[0], pose[1] - nominal[1]
    return (actual[0] + c * dx - s * dy, actual[1] + s * dx + c * dy, pose[2] + dyaw)


def load_layout_file(path: str | Path, scene: Scene) -> Layout:
    """A layout of the user's (``smc replay --layout``): YAML or JSON, checked against
    ``schemas/layout.schema.json``, mapping object -> ``[x, y, z, yaw]`` [m, m, m, rad] or
    ``[x, y, yaw]`` (z: the object's nominal height). Objects left out are absent. A mobile
    base's start is ``robot: [x, y, yaw]`` (default: the scene's nominal start)."""
    p = Path(path)
    try:
        text = p.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"{p}: cannot read layout: {exc}") from exc
    doc = parse_yaml(text, str(p), SceneError)
    check_yaml(doc, "layout", SceneError)
    names = [o.name for o in scene.objects]
    layout: Layout = {}
    for name, values in doc.data.items():
        if name == ROBOT_KEY and scene.robot.base is not None:
            pose = tuple(float(v) for v in values)
            if len(pose) != 3:
                raise SceneError(
                    f"{p}: {doc.where((name,))}: expected the base's start [x, y, yaw], "
                    f"found {len(pose)} numbers"
                )
            layout[ROBOT_KEY] = (pose[0], pose[1], 0.0, pose[2])
            continue
        if name not in names:
            raise SceneError(
                f"{p}: {doc.where((name,), of_key=True)}: no object {name!r} in scene "
                f"{scene.name} (objects: {', '.join(names)})"
            )
        pose = tuple(float(v) for v in values)
        if len(pose) == 3:  # [x, y, yaw]: z from the scene file
            pose = (pose[0], pose[1], scene.object(name).pose[2], pose[2])
        x, y, z, yaw = pose
        layout[name] = (x, y, z, yaw)
    if ROBOT_KEY not in layout and scene.start is not None:
        x, y, yaw = scene.start.pose
        layout[ROBOT_KEY] = (x, y, 0.0, yaw)
    return layout


def _overlaps(scene: Scene, layout: Layout, gap: float) -> bool:
    objs = [o for o in scene.objects if o.name in layout]
    for i, a in enumerate(objs):
        for b in objs[i + 1 :]:
            pa, pb = layout[a.name], layout[b.name]
            if math.hypot(pa[0] - pb[0], pa[1] - pb[1]) < (
                a.footprint_radius + b.footprint_radius + gap
            ):
                return True
    return False
