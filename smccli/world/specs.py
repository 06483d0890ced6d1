"""What a scene declares, as data: its objects, furniture, doors, camera, a mobile base's
start, and the :class:`Scene` itself (built by :mod:`smccli.world.scene`).

World frame: origin at the robot's base on the table top (z = 0), x away from the robot, z up.
An object's pose is that of its bounding-box centre: ``(x, y, z, yaw)`` [m, m, m, rad].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import mujoco

from smccli.errors import SceneError
from smccli.world.compiled import compile_mjcf
from smccli.world.criteria import SuccessCriterion
from smccli.world.noise import IDEAL, SensorNoise
from smccli.world.robot import Robot

SHAPES = ("box", "cylinder", "pyramid", "open_box", "scale", "mug")
"""The shapes an object of a scene file may have."""

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
class StartSpec:
    """Where a mobile base starts: a nominal pose and uniform ranges around nothing (absolute
    intervals, as objects' ranges)."""

    pose: tuple[float, float, float]
    """Nominal ``(x, y, yaw)`` [m, m, rad]."""
    range_x: tuple[float, float]
    range_y: tuple[float, float]
    range_yaw: tuple[float, float]


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
    assets: tuple[tuple[str, bytes], ...] = ()
    """The files the MJCF names (a vendor robot's meshes and textures), as (the name in
    :attr:`mjcf`, bytes): the model compiles from them where those files are not (a log's
    ``asset:<name>`` attachments). Empty when the MJCF names no file."""

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
        """The MJCF compiled into a fresh model (:func:`~smccli.world.compiled.compile_mjcf`:
        a copy of the one this process compiled from the same text and files)."""
        try:
            return compile_mjcf(self.mjcf, dict(self.assets))
        except ValueError as exc:
            raise SceneError(f"scene {self.name}: MJCF does not compile: {exc}") from exc
