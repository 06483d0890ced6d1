"""Reading a scene file (``scene.yaml``, checked against ``schemas/scene.schema.json``) into a
:class:`~smccli.world.specs.Scene`, with SceneError naming the key and line of what the schema
cannot check (names that must exist, ordered ranges)."""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping, Sequence
from typing import Any

import mujoco
import numpy as np

from smccli.errors import SceneError
from smccli.schemas import KeyPath, parse_yaml, validate_yaml
from smccli.world.criteria import GROUPS, Condition, Group, SuccessCriterion
from smccli.world.noise import parse_noise
from smccli.world.robot import Robot
from smccli.world.specs import (
    HIDDEN_GROUP,
    ROBOT_KEY,
    CameraSpec,
    DoorSpec,
    FurnitureSpec,
    ObjectSpec,
    Scene,
    StartSpec,
)


def read_scene_yaml(text: str, where: str) -> dict[str, Any]:
    """The scene file's data, checked against ``schemas/scene.schema.json``."""
    raw: dict[str, Any] = validate_yaml(text, "scene", where, SceneError)
    return raw


def key_at(yaml_text: str, where: str, path: KeyPath) -> str:
    """``<file>: <key path> (line n)`` for a problem the schema cannot see."""
    # Parsed again only when there is a problem to report.
    return f"{where}: {parse_yaml(yaml_text, where, SceneError).where(path)}"


def _vec(values: Any) -> tuple[float, ...]:
    return tuple(float(v) for v in values)


def parse_declarations(
    raw: Mapping[str, Any], where: str, yaml_text: str
) -> tuple[tuple[ObjectSpec, ...], CameraSpec, str | None, tuple[SuccessCriterion, ...]]:
    """The objects, camera, scale and success criteria of a schema-valid scene file;
    SceneError for what the schema cannot check (names that must exist, ordered ranges)."""
    objects: list[ObjectSpec] = []
    for i, o in enumerate(raw["objects"]):
        name, shape = str(o["name"]), str(o["shape"])
        if name == ROBOT_KEY:
            raise SceneError(
                f"{key_at(yaml_text, where, ('objects', i, 'name'))}: {ROBOT_KEY!r} is reserved "
                "(a layout's key for the mobile base's start)"
            )
        if name in (ob.name for ob in objects):
            raise SceneError(
                f"{key_at(yaml_text, where, ('objects', i, 'name'))}: "
                f"duplicate object name {name!r}"
            )
        x, y, z, yaw = _vec(o["pose"])
        ranges = _ranges(o.get("range"), (x, y, yaw), ("objects", i), where, yaml_text)
        sx, sy, sz = _vec(o["size"])
        if shape == "mug" and sx <= sy:
            raise SceneError(
                f"{key_at(yaml_text, where, ('objects', i, 'size'))}: a mug's size x (body "
                f"diameter + handle reach) must exceed its size y (body diameter), "
                f"found x {sx:g} <= y {sy:g}"
            )
        r, g, b, a = _vec(o.get("rgba", (0.5, 0.5, 0.5, 1.0)))
        objects.append(
            ObjectSpec(
                name=name,
                shape=shape,
                size=(sx, sy, sz),
                rgba=(r, g, b, a),
                mass=float(o.get("mass", 0.1)),
                pose=(x, y, z, yaw),
                range_x=ranges["x"],
                range_y=ranges["y"],
                range_yaw=ranges["yaw"],
                fixed=bool(o.get("fixed", shape == "scale")),
                wall=float(o.get("wall", 0.01)),
                on=None if o.get("rests_on") is None else str(o["rests_on"]),
            )
        )
    names = [o.name for o in objects]
    sensors = raw.get("sensors") or {}
    cam = sensors.get("camera") or {}
    camera = CameraSpec(
        name=str(cam.get("name", "sensor_camera")),
        width=int(cam.get("width", 320)),
        height=int(cam.get("height", 240)),
        rate=float(cam.get("rate", 10.0)),
        at_marks=bool(cam.get("at_marks", False)),
    )
    scale = sensors.get("scale")
    if scale is not None:
        scales = [o.name for o in objects if o.shape == "scale"]
        if scale not in scales:
            raise SceneError(
                f"{key_at(yaml_text, where, ('sensors', 'scale'))}: no object {scale!r} of shape "
                f"scale (scales: {', '.join(scales) or 'none'})"
            )
    places = dict(_places(raw))
    variants = [str(v) for v in (raw.get("variants") or {})]
    success = []
    for task, crit in (raw.get("success") or {}).items():
        variant = crit.get("variant")
        if variant is not None and variant not in variants:
            raise SceneError(
                f"{key_at(yaml_text, where, ('success', task, 'variant'))}: no variant "
                f"{variant!r} (variants: {', '.join(variants) or 'none'})"
            )
        groups = []
        for key in GROUPS:
            if key in crit:
                at = ("success", task, key)
                groups.append(_group(key, crit[key], at, yaml_text, where, places, names))
        success.append(SuccessCriterion(str(task), Group("all_of", tuple(groups)), variant))
    return tuple(objects), camera, scale, tuple(success)


def _group(
    kind: str,
    raw: Sequence[Mapping[str, Any]],
    at: KeyPath,
    yaml_text: str,
    where: str,
    places: Mapping[str, Any],
    names: Sequence[str],
) -> Group:
    """A success criterion's group ``kind`` of conditions and nested groups, checked
    against the scene's places and objects (SceneError naming the key and line)."""
    items: list[Condition | Group] = []
    for j, c in enumerate(raw):
        here = (*at, j)
        nested = [k for k in GROUPS if k in c]
        if nested:
            k = nested[0]
            items.append(_group(k, c[k], (*here, k), yaml_text, where, places, names))
        elif "robot_at" in c:
            if c["robot_at"] not in places:
                raise SceneError(
                    f"{key_at(yaml_text, where, (*here, 'robot_at'))}: "
                    f"no place {c['robot_at']!r} (places: {', '.join(places) or 'none'})"
                )
            tol = (
                float(c.get("position_tolerance", 0.1)),
                math.radians(float(c.get("yaw_tolerance_deg", 10.0))),
            )
            items.append(Condition(ROBOT_KEY, "at", str(c["robot_at"]), tol))
        else:
            for role in ("object", "target"):
                if c[role] not in names:
                    raise SceneError(
                        f"{key_at(yaml_text, where, (*here, role))}: "
                        f"no object {c[role]!r} (objects: {', '.join(names)})"
                    )
            items.append(Condition(str(c["object"]), str(c["relation"]), str(c["target"])))
    return Group(kind, tuple(items))


def _ranges(
    rng: Mapping[str, Any] | None,
    nominal: tuple[float, float, float],
    at: KeyPath,
    where: str,
    yaml_text: str,
) -> dict[str, tuple[float, float]]:
    """Randomisation ranges of x, y, yaw (``range`` under the key path ``at``); a coordinate
    left out stays at its ``nominal`` value. SceneError for a range whose low is above its
    high."""
    ranges = {}
    for axis, value in zip(("x", "y", "yaw"), nominal, strict=True):
        lo, hi = _vec((rng or {}).get(axis, (value, value)))
        if lo > hi:
            raise SceneError(
                f"{key_at(yaml_text, where, (*at, 'range', axis))}: "
                f"expected [low, high], found low {lo:g} above high {hi:g}"
            )
        ranges[axis] = (lo, hi)
    return ranges


def _places(raw: Mapping[str, Any]) -> tuple[tuple[str, tuple[float, float, float]], ...]:
    return tuple(
        (str(n), (float(p[0]), float(p[1]), float(p[2])))
        for n, p in (raw.get("places") or {}).items()
    )


def _regions(
    raw: Mapping[str, Any], where: str, yaml_text: str
) -> tuple[tuple[str, tuple[tuple[float, float, float, float], ...]], ...]:
    out: list[tuple[str, tuple[tuple[float, float, float, float], ...]]] = []
    for name, rects in (raw.get("regions") or {}).items():
        boxes = []
        for j, r in enumerate(rects):
            x0, x1, y0, y1 = (float(v) for v in r)
            if x0 >= x1 or y0 >= y1:
                raise SceneError(
                    f"{key_at(yaml_text, where, ('regions', name, j))}: expected "
                    "[x_min, x_max, y_min, y_max] with min < max"
                )
            boxes.append((x0, x1, y0, y1))
        out.append((str(name), tuple(boxes)))
    return tuple(out)


def _start(raw: Mapping[str, Any], where: str, yaml_text: str, robot: Robot) -> StartSpec | None:
    st = raw.get("start")
    if st is None:
        return None
    if robot.base is None:
        raise SceneError(
            f"{key_at(yaml_text, where, ('start',))}: a start pose is for a mobile base; robot "
            f"{robot.name!r} has none"
        )
    x, y, yaw = _vec(st["pose"])
    ranges = _ranges(st.get("range"), (x, y, yaw), ("start",), where, yaml_text)
    return StartSpec((x, y, yaw), ranges["x"], ranges["y"], ranges["yaw"])


def _variants(
    raw: Mapping[str, Any], objects: tuple[ObjectSpec, ...], where: str, yaml_text: str
) -> tuple[tuple[str, tuple[str, ...]], ...]:
    names = [o.name for o in objects]
    out = []
    for variant, members in (raw.get("variants") or {}).items():
        for j, n in enumerate(members):
            if n not in names:
                raise SceneError(
                    f"{key_at(yaml_text, where, ('variants', variant, j))}: "
                    f"no object {n!r} (objects: {', '.join(names)})"
                )
        out.append((str(variant), tuple(str(n) for n in members)))
    return tuple(out)


def scene_from_file(
    raw: Mapping[str, Any],
    yaml_text: str,
    mjcf: str,
    where: str,
    robot: Robot,
    model: mujoco.MjModel,
) -> Scene:
    """The Scene a parsed scene file, its model text and its robot declare."""
    objects, camera, scale, success = parse_declarations(raw, where, yaml_text)
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera.name) < 0:
        raise SceneError(f"{where}: camera {camera.name!r} not in the MJCF")
    hidden = [
        mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom {g}"
        for g in np.flatnonzero(model.geom_group == HIDDEN_GROUP)
    ]
    if hidden:
        raise SceneError(
            f"{where}: geom {', '.join(hidden)} in group {HIDDEN_GROUP}, which no sensor sees "
            f"(smc's own: parked objects, the teleop marker); use groups 0-{HIDDEN_GROUP - 1}"
        )
    return Scene(
        name=str(raw["name"]),
        yaml_path=None,
        yaml_text=yaml_text,
        mjcf=mjcf,
        digest=_digest(yaml_text, mjcf),
        objects=objects,
        camera=camera,
        scale=scale,
        robot=robot,
        success=success,
        description=str(raw.get("description", "")),
        variants=_variants(raw, objects, where, yaml_text),
        start=_start(raw, where, yaml_text, robot),
        places=_places(raw),
        regions=_regions(raw, where, yaml_text),
        perception=tuple(
            (k, tuple(v) if isinstance(v, list) else v)
            for k, v in sorted((raw.get("perception") or {}).items())
        ),
        furniture=_furniture(raw, objects, model, where, yaml_text),
        doors=_doors(raw, model, where, yaml_text),
        noise=parse_noise(
            (raw.get("sensors") or {}).get("noise"), key_at(yaml_text, where, ("sensors", "noise"))
        ),
    )


def _furniture(
    raw: Mapping[str, Any],
    objects: Sequence[ObjectSpec],
    model: mujoco.MjModel,
    where: str,
    yaml_text: str,
) -> tuple[FurnitureSpec, ...]:
    """The scene file's ``furniture``: MJCF bodies a layout moves; objects ``on`` them."""
    out = []
    for i, f in enumerate(raw.get("furniture") or ()):
        name = str(f["name"])
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name) < 0:
            raise SceneError(
                f"{key_at(yaml_text, where, ('furniture', i, 'name'))}: "
                f"the MJCF has no body {name!r}"
            )
        x, y, z, yaw = _vec(f["pose"])
        ranges = _ranges(f.get("range"), (x, y, yaw), ("furniture", i), where, yaml_text)
        out.append(FurnitureSpec(name, (x, y, z, yaw), ranges["x"], ranges["y"], ranges["yaw"]))
    names = {f.name for f in out}
    for i, o in enumerate(objects):
        if o.on is not None and o.on not in names:
            raise SceneError(
                f"{key_at(yaml_text, where, ('objects', i, 'rests_on'))}: no furniture {o.on!r} "
                f"(furniture: {', '.join(sorted(names)) or 'none'})"
            )
    return tuple(out)


def _doors(
    raw: Mapping[str, Any], model: mujoco.MjModel, where: str, yaml_text: str
) -> tuple[DoorSpec, ...]:
    """The scene file's ``doors``, their joint and handle checked against the MJCF."""
    out = []
    for i, d in enumerate(raw.get("doors") or ()):
        for key, kind in (
            ("joint", mujoco.mjtObj.mjOBJ_JOINT),
            ("handle", mujoco.mjtObj.mjOBJ_GEOM),
        ):
            if mujoco.mj_name2id(model, kind, str(d[key])) < 0:
                raise SceneError(
                    f"{key_at(yaml_text, where, ('doors', i, key))}: the MJCF has no "
                    f"{'joint' if key == 'joint' else 'geom'} {d[key]!r}"
                )
        out.append(DoorSpec(str(d["name"]), str(d["joint"]), float(d["open"]), str(d["handle"])))
    return tuple(out)


def _digest(yaml_text: str, mjcf_text: str) -> str:
    h = hashlib.sha256()
    h.update(yaml_text.encode())
    h.update(b"\0")
    h.update(mjcf_text.encode())
    return "sha256:" + h.hexdigest()
