"""Scenes: an MJCF model (table, camera) plus a scene file (YAML) naming the robot and the objects.

The robot's MJCF (:mod:`smccli.world.robot`) is included beside the scene's, its root at the
world origin; the objects are built from the scene file with ``mujoco.MjSpec`` so their look,
mass and pose have one source of truth. A :class:`Scene` carries the flattened,
self-contained MJCF text of the whole model and the robot file's text, so a log can embed
them and :func:`load_scene_from_text` can rebuild the scene without the original files.

World frame: origin at the robot's base on the table top (z = 0), x away from the robot, z up.
An object's pose is that of its bounding-box centre: ``(x, y, z, yaw)`` [m, m, m, rad].
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import mujoco
import numpy as np

from smccli.errors import LogError, SceneError
from smccli.schemas import KeyPath, parse_yaml, validate_yaml
from smccli.world.noise import IDEAL, SensorNoise, parse_noise
from smccli.world.objects import add_object
from smccli.world.robot import (
    DEFAULT_ROBOT,
    ROBOTS_DIR,
    Robot,
    check_robot,
    kinematics_digest,
    load_robot,
    resolve_robot_path,
    robot_from_text,
)

SCENES_DIR = Path(__file__).parent / "scenes"
SHAPES = ("box", "cylinder", "pyramid", "open_box", "scale", "mug")
RELATIONS = ("on_top_of", "inside")

Layout = dict[str, tuple[float, float, float, float]]
"""Object name -> pose ``(x, y, z, yaw)`` [m, m, m, rad] of its bounding-box centre; for a
mobile base, the key :data:`ROBOT_KEY` holds its start pose ``(x, y, 0, yaw)``."""
HIDDEN_GROUP = 5
"""The geom group no sensor sees (camera, lidar): smc's own, for the teleop marker and
parked objects (the viewer still shows it). Scene and robot files may not use it."""
ROBOT_KEY = "robot"
"""The layout key of a mobile base's start pose (no object may have this name)."""


@dataclass(frozen=True, slots=True)
class ObjectSpec:
    """One object of a scene, as the scene file describes it."""

    name: str
    """Body name in the model."""
    shape: str
    """One of :data:`SHAPES`."""
    size: tuple[float, float, float]
    """Full extents of the bounding box along x, y, z [m] (cylinder: x = y = diameter; mug:
    x = body diameter + handle reach, y = body diameter)."""
    rgba: tuple[float, float, float, float]
    """Colour, each in [0, 1]."""
    mass: float
    """Mass [kg] (for ``scale``: of the platform)."""
    pose: tuple[float, float, float, float]
    """Nominal pose ``(x, y, z, yaw)`` of the bounding-box centre [m, m, m, rad]."""
    range_x: tuple[float, float]
    """Randomisation range of x [m]; equal bounds mean fixed."""
    range_y: tuple[float, float]
    """Randomisation range of y [m]."""
    range_yaw: tuple[float, float]
    """Randomisation range of yaw [rad]."""
    fixed: bool = False
    """Welded to the world (no free joint): scales, and anything the user wants static."""
    on: str | None = None
    """The furniture it rests on (its pose and ranges at the furniture's nominal pose)."""
    wall: float = 0.01
    """Wall and floor thickness of an ``open_box`` [m]."""

    @property
    def footprint_radius(self) -> float:
        """Radius of the circle circumscribing the object's footprint [m]."""
        return 0.5 * math.hypot(self.size[0], self.size[1])


@dataclass(frozen=True, slots=True)
class Condition:
    """``object`` rests ``relation`` (on top of / inside) ``target``; or, with relation
    ``at``, the mobile base (object :data:`ROBOT_KEY`) stands at the place ``target``
    within ``tolerance``."""

    object: str
    """Name of the object that was moved (:data:`ROBOT_KEY` for ``at``)."""
    relation: str
    """One of :data:`RELATIONS`, or ``at``."""
    target: str
    """Name of the object it must rest on or in, or of the place (``at``)."""
    tolerance: tuple[float, float] = (0.1, math.radians(10))
    """``at``: largest position [m] and heading [rad] error."""


@dataclass(frozen=True, slots=True)
class StartSpec:
    """Where a mobile base starts: a nominal pose and uniform ranges around nothing (absolute
    intervals, as objects' ranges)."""

    pose: tuple[float, float, float]
    """Nominal ``(x, y, yaw)`` [m, m, rad]."""
    range_x: tuple[float, float]
    range_y: tuple[float, float]
    range_yaw: tuple[float, float]


GROUPS = ("all_of", "any_of", "none_of")
"""How a group combines its items: every one holds, at least one, none."""


@dataclass(frozen=True, slots=True)
class Group:
    """Conditions combined (nestable): ``all_of`` every item holds, ``any_of`` at least
    one, ``none_of`` none."""

    kind: str
    """One of :data:`GROUPS`."""
    items: tuple[Condition | Group, ...]

    def conditions(self, negated: bool = False) -> Iterator[Condition]:
        """The conditions the task makes hold (``negated``: those it must not)."""
        for item in self.items:
            inner = negated != (self.kind == "none_of")
            if isinstance(item, Group):
                yield from item.conditions(inner)
            elif not inner:
                yield item


@dataclass(frozen=True, slots=True)
class SuccessCriterion:
    """A task's success: every key of its criterion holds, ``all_of`` (every item),
    ``any_of`` (at least one) and ``none_of`` (none), items nestable."""

    task: str
    """Task name, e.g. ``cube_on_green``."""
    rule: Group
    """The criterion: ``all_of`` its keys' groups."""
    variant: str | None = None
    """The criterion only counts in layouts of this variant (the arrow the robot was
    shown); None: in every layout."""

    def conditions(self) -> tuple[Condition, ...]:
        """The conditions the task makes hold (not those of a ``none_of``), in file order."""
        return tuple(self.rule.conditions())


@dataclass(frozen=True, slots=True)
class FurnitureSpec:
    """A body of the scene's MJCF that a layout moves as a whole (a wardrobe and its door)."""

    name: str
    """Body name in the MJCF."""
    pose: tuple[float, float, float, float]
    """Nominal pose ``(x, y, z, yaw)`` [m, m, m, rad] (the MJCF's)."""
    range_x: tuple[float, float]
    """Randomisation range of x [m]; equal bounds mean fixed."""
    range_y: tuple[float, float]
    """Randomisation range of y [m]."""
    range_yaw: tuple[float, float]
    """Randomisation range of yaw [rad]."""


@dataclass(frozen=True, slots=True)
class DoorSpec:
    """A door the task opens (evaluation: door_not_opened, handle_slipped)."""

    name: str
    joint: str
    """Its joint in the MJCF."""
    open: float
    """Joint value from which it counts as open [m or rad]."""
    handle: str
    """Its handle's geom."""


@dataclass(frozen=True, slots=True)
class CameraSpec:
    """The RGB-D sensor camera."""

    name: str
    """MJCF camera name."""
    width: int
    """Image width [px]."""
    height: int
    """Image height [px]."""
    rate: float
    """Frame rate [Hz]."""
    at_marks: bool = False
    """Also a frame (and a lidar scan) at each saliency mark while recording."""


@dataclass(frozen=True, slots=True)
class Scene:
    """A built-in or user scene: model text, scene file text and what they declare."""

    name: str
    """Scene name (``pick_place``, …)."""
    yaml_path: Path | None
    """The scene file, or None when rebuilt from text (a log)."""
    yaml_text: str
    """The scene file's text, verbatim."""
    mjcf: str
    """Flattened self-contained MJCF of the whole model, objects included."""
    digest: str
    """``sha256:<hex>`` of the scene file text and the MJCF text."""
    objects: tuple[ObjectSpec, ...]
    """The objects, in scene-file order."""
    camera: CameraSpec
    """The sensor camera."""
    scale: str | None
    """Name of the scale object (its force sensor is ``<name>_force``), or None."""
    robot: Robot
    """The robot the scene holds."""
    success: tuple[SuccessCriterion, ...]
    """One criterion per task."""
    description: str = ""
    """One line for ``smc scenes``."""
    variants: tuple[tuple[str, tuple[str, ...]], ...] = ()
    """Named subsets of the optional objects, ``(name, object names)``. A layout holds the
    objects of one variant plus every object no variant names (tables, bins, scales);
    the others are parked out of sight. Empty: every object is always present."""
    start: StartSpec | None = None
    """A mobile base's start pose and its randomisation; None: the origin."""
    places: tuple[tuple[str, tuple[float, float, float]], ...] = ()
    """Named base poses ``(x, y, yaw)`` [m, m, rad]: goals of ``at`` conditions and of the
    scripted operator's ``go_to`` steps."""
    regions: tuple[tuple[str, tuple[tuple[float, float, float, float], ...]], ...] = ()
    """Named areas of the floor (rooms), each a union of rectangles ``(x_min, x_max, y_min,
    y_max)`` [m]; used to say in which room a base ended (evaluation, inspect)."""
    doors: tuple[DoorSpec, ...] = ()
    """Doors the task opens (scene.yaml ``doors``), for the failure causes."""
    furniture: tuple[FurnitureSpec, ...] = ()
    """Bodies of the MJCF a layout moves as a whole; objects ``on`` them move along."""
    noise: SensorNoise = IDEAL
    """The sensor models (``sensors.noise``, :mod:`smccli.world.noise`): ideal by default."""
    perception: tuple[tuple[str, object], ...] = ()
    """Perception settings the scene's trees start with (scene.yaml ``perception``), as
    (name, value) pairs of :class:`~smccli.perception.params.PerceptionParams` fields."""

    def place(self, name: str) -> tuple[float, float, float]:
        """The place called ``name``; SceneError listing the valid names otherwise."""
        table = dict(self.places)
        if name not in table:
            raise SceneError(
                f"scene {self.name}: no place {name!r} (places: {', '.join(table) or 'none'})"
            )
        return table[name]

    def region_of(self, x: float, y: float) -> str | None:
        """The region (room) holding the floor point (x, y) [m], None outside all."""
        for name, rects in self.regions:
            if any(x0 <= x <= x1 and y0 <= y <= y1 for x0, x1, y0, y1 in rects):
                return name
        return None

    def variant_objects(self, variant: str | None) -> tuple[str, ...]:
        """Objects present in ``variant`` (all objects when None or without variants)."""
        if variant is None or not self.variants:
            return tuple(o.name for o in self.objects)
        table = dict(self.variants)
        if variant not in table:
            raise SceneError(
                f"scene {self.name}: no variant {variant!r} (variants: {', '.join(table)})"
            )
        optional = {n for _, names in self.variants for n in names}
        return tuple(
            o.name for o in self.objects if o.name not in optional or o.name in table[variant]
        )

    @property
    def poi(self) -> str:
        """Name of the POI site (the end-effector)."""
        return self.robot.poi

    def object(self, name: str) -> ObjectSpec:
        """The object called ``name``; SceneError listing the valid names otherwise."""
        for obj in self.objects:
            if obj.name == name:
                return obj
        valid = ", ".join(o.name for o in self.objects)
        raise SceneError(f"scene {self.name}: no object {name!r} (objects: {valid})")

    def model(self) -> mujoco.MjModel:
        """Compile the MJCF into a fresh model."""
        try:
            return mujoco.MjModel.from_xml_string(self.mjcf)
        except ValueError as exc:
            raise SceneError(f"scene {self.name}: MJCF does not compile: {exc}") from exc


def builtin_names() -> list[str]:
    """Names of the built-in scenes."""
    return sorted(p.parent.name for p in SCENES_DIR.glob("*/scene.yaml"))


def list_scenes() -> list[Scene]:
    """All built-in scenes."""
    return [load_scene(n) for n in builtin_names()]


def load_scene(name_or_path: str | Path) -> Scene:
    """A built-in scene by name, or a user scene by the path of its ``scene.yaml``."""
    text = str(name_or_path)
    if text in builtin_names():
        path = SCENES_DIR / text / "scene.yaml"
    else:
        path = Path(name_or_path)
        if not path.is_file():
            raise SceneError(
                f"{text}: no such scene (built-in scenes: {', '.join(builtin_names())}; "
                "or give the path of a scene.yaml)"
            )
    yaml_text = path.read_text()
    raw = _parse_yaml(yaml_text, str(path))
    mjcf_file = path.parent / str(raw.get("mjcf", "scene.xml"))
    if not mjcf_file.is_file():
        raise SceneError(f"{path}: MJCF file {mjcf_file} not found")
    ref = raw.get("robot", DEFAULT_ROBOT)
    try:
        if isinstance(ref, str):
            try:
                robot_file = resolve_robot_path(ref, relative_to=path.parent)
            except SceneError as exc:
                raise SceneError(f"{_at(yaml_text, str(path), ('robot',))}: {exc}") from None
            robot = load_robot(robot_file)
            # The robot first: its <option> and <compiler> apply, the scene's may refine them.
            spec = mujoco.MjSpec.from_string(
                f"<mujoco model={quoteattr(str(raw['name']))}>"
                f"<include file={quoteattr(str(robot.mjcf_path))}/>"
                f"<include file={quoteattr(str(mjcf_file.resolve()))}/></mujoco>"
            )
        else:  # a scene file from before robot files: its MJCF includes the built-in arm
            robot = load_robot(DEFAULT_ROBOT)
            spec = mujoco.MjSpec.from_file(str(mjcf_file))
    except ValueError as exc:
        raise SceneError(f"{mjcf_file}: invalid MJCF: {' '.join(str(exc).split())}") from exc
    scene = _build(raw, yaml_text, spec, str(path), robot)
    return _replace_path(scene, path)


def load_scene_from_text(
    yaml_text: str, mjcf_text: str, robot_yaml: str | None = None, *, log: str | None = None
) -> Scene:
    """Rebuild a scene from the texts a log embeds (``Scene.yaml_text``, ``Scene.mjcf``,
    ``Robot.yaml_text``). A log from before robot files has no robot file: its scene holds
    the built-in robot its scene file names (the arm).

    ``log``: the log file the texts were attached to; errors are then LogError naming it
    and the attachment (``demo.mcap: attachment scene.yaml: ...``), else SceneError.
    """
    at_yaml = f"{log}: attachment scene.yaml" if log else "<embedded scene.yaml>"
    at_xml = f"{log}: attachment scene.xml" if log else "<embedded MJCF>"
    at_robot = f"{log}: attachment robot.yaml" if log else "<embedded robot.yaml>"
    try:
        raw = _parse_yaml(yaml_text, at_yaml)
        try:
            model = mujoco.MjModel.from_xml_string(mjcf_text)
        except ValueError as exc:
            raise SceneError(
                f"{at_xml}: MuJoCo rejects the MJCF ({' '.join(str(exc).split())})"
            ) from exc
        if robot_yaml is None:
            ref = raw.get("robot", DEFAULT_ROBOT)
            name = ref if isinstance(ref, str) else DEFAULT_ROBOT
            if not (ROBOTS_DIR / name / "robot.yaml").is_file():
                raise SceneError(f"{at_robot} missing (the scene names robot {name!r})")
            robot_yaml = (ROBOTS_DIR / name / "robot.yaml").read_text()
        robot, doc = robot_from_text(robot_yaml, at_robot)
        check_robot(robot, model, doc, "attachment scene.xml", SceneError)
        return _scene(raw, yaml_text, mjcf_text, at_yaml, robot, model)
    except SceneError as exc:
        if log is None:
            raise
        raise LogError(str(exc)) from exc


def scene_of_log(attachments: Mapping[str, bytes], log: str | Path) -> Scene:
    """The scene a log's attachments hold (``scene.yaml``, ``scene.xml``, ``robot.yaml``);
    LogError naming the log and the attachment when one is missing or wrong."""
    texts: dict[str, str | None] = {}
    what = {"scene.xml": "the scene's MJCF", "scene.yaml": "the scene file"}
    for name in ("scene.xml", "scene.yaml", "robot.yaml"):
        data = attachments.get(name)
        if data is None:
            if name in what:  # robot.yaml: older logs have none, their robot is the arm
                raise LogError(f"{log}: attachment {name} missing ({what[name]})")
            texts[name] = None
            continue
        try:
            texts[name] = data.decode() if isinstance(data, bytes) else str(data)
        except UnicodeDecodeError as exc:
            raise LogError(f"{log}: attachment {name}: not UTF-8 text ({exc})") from None
    return load_scene_from_text(
        texts["scene.yaml"] or "",
        texts["scene.xml"] or "",
        texts["robot.yaml"],
        log=str(log),
    )


def robot_identity(scene: Scene, model: mujoco.MjModel | None = None) -> dict[str, str]:
    """What a tree records of the robot it was taught on: name and kinematics digest."""
    model = model or scene.model()
    return {"name": scene.robot.name, "kinematics": kinematics_digest(scene.robot, model)}


def sensor_identity(scene: Scene, model: mujoco.MjModel | None = None) -> dict[str, Any]:
    """What a tree records of the sensors it perceives through: the camera's resolution and
    vertical field of view [deg], and whether the scene has a scale."""
    model = model or scene.model()
    cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, scene.camera.name)
    return {
        "camera": {
            "width": scene.camera.width,
            "height": scene.camera.height,
            "fovy": round(float(model.cam_fovy[cam]), 6),
        },
        "scale": scene.scale is not None,
    }


# --- scene file parsing ---------------------------------------------------------------


def _parse_yaml(text: str, where: str) -> dict[str, Any]:
    """The scene file's data, checked against ``schemas/scene.schema.json``."""
    raw: dict[str, Any] = validate_yaml(text, "scene", where, SceneError)
    return raw


def _at(yaml_text: str, where: str, path: KeyPath) -> str:
    """``<file>: <key path> (line n)`` for a problem the schema cannot see."""
    # Parsed again only when there is a problem to report.
    return f"{where}: {parse_yaml(yaml_text, where, SceneError).where(path)}"


def _vec(values: Any) -> tuple[float, ...]:
    return tuple(float(v) for v in values)


def _parse(
    raw: Mapping[str, Any], where: str, yaml_text: str
) -> tuple[tuple[ObjectSpec, ...], CameraSpec, str | None, tuple[SuccessCriterion, ...]]:
    """The objects, camera, scale and success criteria of a schema-valid scene file;
    SceneError for what the schema cannot check (names that must exist, ordered ranges)."""
    objects: list[ObjectSpec] = []
    for i, o in enumerate(raw["objects"]):
        name, shape = str(o["name"]), str(o["shape"])
        if name == ROBOT_KEY:
            raise SceneError(
                f"{_at(yaml_text, where, ('objects', i, 'name'))}: {ROBOT_KEY!r} is reserved "
                "(a layout's key for the mobile base's start)"
            )
        if name in (ob.name for ob in objects):
            raise SceneError(
                f"{_at(yaml_text, where, ('objects', i, 'name'))}: duplicate object name {name!r}"
            )
        x, y, z, yaw = _vec(o["pose"])
        ranges = _ranges(o.get("range"), (x, y, yaw), ("objects", i), where, yaml_text)
        sx, sy, sz = _vec(o["size"])
        if shape == "mug" and sx <= sy:
            raise SceneError(
                f"{_at(yaml_text, where, ('objects', i, 'size'))}: a mug's size x (body diameter "
                f"+ handle reach) must exceed its size y (body diameter), found x {sx:g} <= "
                f"y {sy:g}"
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
                f"{_at(yaml_text, where, ('sensors', 'scale'))}: no object {scale!r} of shape "
                f"scale (scales: {', '.join(scales) or 'none'})"
            )
    places = dict(_places(raw))
    variants = [str(v) for v in (raw.get("variants") or {})]
    success = []
    for task, crit in (raw.get("success") or {}).items():
        variant = crit.get("variant")
        if variant is not None and variant not in variants:
            raise SceneError(
                f"{_at(yaml_text, where, ('success', task, 'variant'))}: no variant "
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
                    f"{_at(yaml_text, where, (*here, 'robot_at'))}: "
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
                        f"{_at(yaml_text, where, (*here, role))}: "
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
                f"{_at(yaml_text, where, (*at, 'range', axis))}: "
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
                    f"{_at(yaml_text, where, ('regions', name, j))}: expected "
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
            f"{_at(yaml_text, where, ('start',))}: a start pose is for a mobile base; robot "
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
                    f"{_at(yaml_text, where, ('variants', variant, j))}: "
                    f"no object {n!r} (objects: {', '.join(names)})"
                )
        out.append((str(variant), tuple(str(n) for n in members)))
    return tuple(out)


def _build(
    raw: Mapping[str, Any], yaml_text: str, spec: mujoco.MjSpec, where: str, robot: Robot
) -> Scene:
    objects, camera, scale, success = _parse(raw, where, yaml_text)
    for obj in objects:
        add_object(spec, obj)
    try:
        spec.compile()
    except ValueError as exc:
        raise SceneError(f"{where}: model does not compile: {exc}") from exc
    mjcf = spec.to_xml()
    model = mujoco.MjModel.from_xml_string(mjcf)
    return _scene(raw, yaml_text, mjcf, where, robot, model)


def _scene(
    raw: Mapping[str, Any],
    yaml_text: str,
    mjcf: str,
    where: str,
    robot: Robot,
    model: mujoco.MjModel,
) -> Scene:
    """The Scene a parsed scene file, its model text and its robot declare."""
    objects, camera, scale, success = _parse(raw, where, yaml_text)
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
            (raw.get("sensors") or {}).get("noise"), _at(yaml_text, where, ("sensors", "noise"))
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
                f"{_at(yaml_text, where, ('furniture', i, 'name'))}: the MJCF has no body {name!r}"
            )
        x, y, z, yaw = _vec(f["pose"])
        ranges = _ranges(f.get("range"), (x, y, yaw), ("furniture", i), where, yaml_text)
        out.append(FurnitureSpec(name, (x, y, z, yaw), ranges["x"], ranges["y"], ranges["yaw"]))
    names = {f.name for f in out}
    for i, o in enumerate(objects):
        if o.on is not None and o.on not in names:
            raise SceneError(
                f"{_at(yaml_text, where, ('objects', i, 'rests_on'))}: no furniture {o.on!r} "
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
                    f"{_at(yaml_text, where, ('doors', i, key))}: the MJCF has no "
                    f"{'joint' if key == 'joint' else 'geom'} {d[key]!r}"
                )
        out.append(DoorSpec(str(d["name"]), str(d["joint"]), float(d["open"]), str(d["handle"])))
    return tuple(out)


def _replace_path(scene: Scene, path: Path) -> Scene:
    from dataclasses import replace

    return replace(scene, yaml_path=path)


def _digest(yaml_text: str, mjcf_text: str) -> str:
    h = hashlib.sha256()
    h.update(yaml_text.encode())
    h.update(b"\0")
    h.update(mjcf_text.encode())
    return "sha256:" + h.hexdigest()
