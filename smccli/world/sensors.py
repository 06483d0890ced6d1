"""Sensor readings and commands shared by the simulator, the logs, perception and replay.

Times are simulation seconds (float) in memory and integer nanoseconds in logs.
The arm's point of interest (POI) is the end-effector site: ``[x, y, z, yaw]`` in the
world frame [m, m, m, rad] (a mobile manipulator's: in its base's frame), the gripper
pointing down; the gripper opening is in [0, 1] (1 = fully open). A mobile base's pose is
``[x, y, yaw]`` in odometry's frame. Commands and joint readings run at one rate,
:data:`CONTROL_PERIOD`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

CONTROL_PERIOD = 0.01
"""Control period [s] (100 Hz): the simulator takes one command per period and the sensors
are read once per period (the physics timestep comes from the model, 2 ms)."""


@dataclass(frozen=True, slots=True)
class PoiCommand:
    """What an operator (or the tree) asks the Cartesian controller for."""

    t: float
    """Simulation time [s]."""
    target: np.ndarray
    """POI target ``[x, y, z, yaw]``, shape (4,) [m, m, m, rad], world frame."""
    gripper: float
    """Gripper opening command in [0, 1], 1 = open."""
    base: np.ndarray | None = None
    """A mobile manipulator's base target ``[x, y, yaw]``, shape (3,) [m, m, rad], in
    odometry's frame; its ``target`` is then the end effector in the base's frame
    (docs/design.md 9: two POIs). None: the base holds its last target."""


@dataclass(frozen=True, slots=True)
class JointState:
    """Robot joint readings at one instant."""

    t: float
    """Simulation time [s]."""
    names: tuple[str, ...]
    """Joint names, length n."""
    position: np.ndarray
    """Joint positions, shape (n,) [rad or m]."""
    velocity: np.ndarray
    """Joint velocities, shape (n,) [rad/s or m/s]."""
    effort: np.ndarray
    """Actuator forces, shape (n,) [N·m or N]."""


@dataclass(frozen=True, slots=True)
class CameraFrame:
    """One RGB-D image with what is needed to lift it into the world frame."""

    t: float
    """Simulation time [s]."""
    rgb: np.ndarray
    """Colour image, shape (H, W, 3) uint8, RGB order."""
    depth: np.ndarray
    """Depth along the optical axis, shape (H, W) float32 [m]; 0 or inf where nothing was hit."""
    K: np.ndarray
    """Pinhole intrinsics, shape (3, 3) [px]."""
    T_world_camera: np.ndarray
    """Camera pose in the world, shape (4, 4); optical frame: x right, y down, z forward."""
    frame_id: str = "camera"


_RGB_SLOT: Any = CameraFrame.__dict__["rgb"]
"""Where a :class:`CameraFrame` keeps its colour image (the dataclass's slot)."""


class DrawingFrame(CameraFrame):
    """A :class:`CameraFrame` whose colour image is still being drawn when it is made:
    ``rgb`` calls ``fetch`` at its first read, which waits for the rasteriser and reads
    the image back, and keeps what it returns. Everything else reads as the frame's.

    A simulated camera draws the depth first and the colours after it, without waiting
    (:meth:`smccli.world.camera.CameraRenderer.render`): whoever reads the depth first
    (perception lifts, crops, fits the table and clusters, then gathers the colours of
    the points it kept) computes while the colours are drawn, on the other core.
    """

    __slots__ = ("_fetch",)
    _fetch: Callable[[], np.ndarray] | None

    def __init__(
        self,
        t: float,
        rgb: np.ndarray | None,
        depth: np.ndarray,
        K: np.ndarray,
        T_world_camera: np.ndarray,
        frame_id: str = "camera",
        *,
        fetch: Callable[[], np.ndarray] | None = None,
    ) -> None:
        object.__setattr__(self, "_fetch", fetch)
        CameraFrame.__init__(self, t, rgb, depth, K, T_world_camera, frame_id)  # type: ignore[arg-type]

    def _get_rgb(self) -> np.ndarray:
        fetch = self._fetch
        if fetch is not None:
            _RGB_SLOT.__set__(self, fetch())
            object.__setattr__(self, "_fetch", None)
        rgb: np.ndarray = _RGB_SLOT.__get__(self, CameraFrame)
        return rgb

    def _set_rgb(self, value: np.ndarray) -> None:  # the dataclass's __init__ sets it
        _RGB_SLOT.__set__(self, value)

    rgb = property(_get_rgb, _set_rgb)  # type: ignore[assignment]


@dataclass(frozen=True, slots=True)
class SaliencyMark:
    """A saliency marker: the operator's button or an automatic detector."""

    t: float
    """Simulation time [s]."""
    source: str
    """``"operator"`` or ``"auto"``."""
    label: str = ""


@dataclass(frozen=True, slots=True)
class RobotGeometry:
    """The robot's own collision shapes at one instant, for removing its points from clouds.

    Computed from the robot's kinematic model and joint readings (allowed: it is the
    robot's own body, not simulator knowledge of the objects).
    """

    centers: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """Centres of bounding spheres, shape (m, 3) [m], world frame."""
    radii: np.ndarray = field(default_factory=lambda: np.zeros((0,)))
    """Radii of those spheres, shape (m,) [m]."""
