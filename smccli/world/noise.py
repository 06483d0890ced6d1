"""Sensor models: what a real RGB-D camera, scale and lidar add to the simulator's readings.

A scene file chooses them per sensor (``sensors.noise``): the profile ``ideal`` (the
simulator's exact readings; the default) or ``realistic`` (below), optionally with
per-sensor overrides::

    sensors:
      noise: realistic
      # or: noise: {profile: realistic, camera: {exposure: 0.25}, lidar: {dropout: 0.05}}

``realistic`` is a structured-light RGB-D camera at arm's length, a kitchen scale and a
2D lidar of the RPLIDAR class:

- **Depth**: Gaussian noise along the ray whose σ grows with distance,
  σ(z) = a + b (z − z₀)² (Nguyen, Izadi and Lovell 2012, the Kinect's axial noise:
  a = 1.2 mm, b = 1.9 mm/m², z₀ = 0.4 m; 2.4 mm at 1.2 m).
- **Invalid pixels** (depth 0, as drivers report them): at depth edges (a jump over
  1.5 cm to a neighbour: the projector's shadow and mixed pixels), half of them; on dark
  surfaces (luma under 0.12: too little IR returns), 30 %; anywhere, 0.2 %. Shiny surfaces
  are not modelled: MuJoCo's colour says nothing about specularity (a white matte box
  renders saturated like a highlight would, and drivers see those well), and the built-in
  scenes give no object a shiny material.
- **Colour**: per-pixel Gaussian noise (σ = 2 % of full scale), and per episode an exposure
  gain in [0.8, 1.2] and a white balance gain per channel in [0.95, 1.05] (the light and the
  auto exposure differ from one episode to the next).
- **Scale**: σ = 0.5 g per reading, a tare error in ±1 g and a drift in ±2 g/min per
  episode.
- **Lidar**: σ = 1 cm + 1 % of the range, 1 % of the beams lost (no return).

Every draw comes from one generator per episode, seeded (``Sim.reset``): a campaign stays
reproducible. ``ideal`` draws nothing and returns the readings untouched, to the bit.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from smccli.errors import SceneError
from smccli.world.lidar import LidarReading
from smccli.world.sensors import CameraFrame


@dataclass(frozen=True, slots=True)
class CameraNoise:
    """RGB-D camera model (zeros: ideal)."""

    depth_a: float = 0.0
    """σ of the depth at ``depth_z0`` [m]."""
    depth_b: float = 0.0
    """Growth of σ with the squared distance beyond ``depth_z0`` [1/m]."""
    depth_z0: float = 0.4
    """Distance where σ is smallest [m]."""
    edge_jump: float = 0.015
    """A depth jump to a 4-neighbour over this marks an edge pixel [m]."""
    edge_dropout: float = 0.0
    """Probability an edge pixel is invalid."""
    dark_luma: float = 0.12
    """Luma under this (0-1) is a dark surface."""
    dark_dropout: float = 0.0
    """Probability a dark pixel is invalid."""
    dropout: float = 0.0
    """Probability any pixel is invalid."""
    colour_sigma: float = 0.0
    """Per-pixel colour noise, fraction of full scale."""
    exposure: float = 0.0
    """Per-episode exposure gain drawn in [1 - exposure, 1 + exposure]."""
    white_balance: float = 0.0
    """Per-episode gain of each channel drawn in [1 - white_balance, 1 + white_balance]."""


@dataclass(frozen=True, slots=True)
class ScaleNoise:
    """Scale model [kg, kg/s] (zeros: ideal)."""

    sigma: float = 0.0
    """σ of each reading [kg]."""
    offset: float = 0.0
    """Per-episode tare error drawn in [-offset, offset] [kg]."""
    drift: float = 0.0
    """Per-episode drift rate drawn in [-drift, drift] [kg/s]."""


@dataclass(frozen=True, slots=True)
class LidarNoise:
    """Lidar model (zeros: ideal)."""

    sigma: float = 0.0
    """Range σ at zero range [m]."""
    sigma_rel: float = 0.0
    """Range σ growth, fraction of the range."""
    dropout: float = 0.0
    """Probability a beam returns nothing (inf)."""


@dataclass(frozen=True, slots=True)
class SensorNoise:
    """The sensor models of a scene."""

    profile: str = "ideal"
    camera: CameraNoise = CameraNoise()
    scale: ScaleNoise = ScaleNoise()
    lidar: LidarNoise = LidarNoise()

    @property
    def ideal(self) -> bool:
        """Nothing is added to any reading."""
        return (self.camera, self.scale, self.lidar) == (CameraNoise(), ScaleNoise(), LidarNoise())


IDEAL = SensorNoise()
REALISTIC = SensorNoise(
    profile="realistic",
    camera=CameraNoise(
        depth_a=0.0012,
        depth_b=0.0019,
        edge_dropout=0.5,
        dark_dropout=0.3,
        dropout=0.002,
        colour_sigma=0.02,
        exposure=0.2,
        white_balance=0.05,
    ),
    scale=ScaleNoise(sigma=0.0005, offset=0.001, drift=0.002 / 60),
    lidar=LidarNoise(sigma=0.01, sigma_rel=0.01, dropout=0.01),
)
PROFILES = {"ideal": IDEAL, "realistic": REALISTIC}
"""The named profiles (module docstring)."""


def parse_noise(raw: Any, where: str) -> SensorNoise:
    """``sensors.noise`` of a scene file: a profile name, or ``{profile, camera, scale,
    lidar}`` with per-sensor overrides of the profile's values. ``where``: the file and key
    for errors."""
    if raw is None:
        return IDEAL
    if isinstance(raw, str):
        raw = {"profile": raw}
    if not isinstance(raw, Mapping):
        raise SceneError(f"{where}: expected a profile name or a mapping, found {raw!r}")
    name = str(raw.get("profile", "ideal"))
    if name not in PROFILES:
        raise SceneError(f"{where}: unknown profile {name!r} (profiles: {', '.join(PROFILES)})")
    noise = PROFILES[name]
    parts: dict[str, Any] = {}
    for key in ("camera", "scale", "lidar"):
        over = raw.get(key) or {}
        base = getattr(noise, key)
        valid = {f.name for f in fields(base)}
        bad = sorted(set(over) - valid)
        if bad:
            raise SceneError(
                f"{where}.{key}: unknown key {bad[0]!r} (keys: {', '.join(sorted(valid))})"
            )
        for k, v in over.items():
            if not isinstance(v, int | float) or v < 0:
                raise SceneError(f"{where}.{key}.{k}: expected a number >= 0, found {v!r}")
        parts[key] = replace(base, **{k: float(v) for k, v in over.items()})
    return replace(noise, **parts)


class NoisySensors:
    """One episode's sensor errors: the per-episode draws (exposure, white balance, tare,
    drift) and the generator of the per-reading ones."""

    def __init__(self, noise: SensorNoise, seed: int) -> None:
        self.noise = noise
        self.rng = np.random.default_rng(seed)
        c, s = noise.camera, noise.scale
        self.gain = (
            self.rng.uniform(1 - c.exposure, 1 + c.exposure)
            * self.rng.uniform(1 - c.white_balance, 1 + c.white_balance, size=3)
            if not noise.ideal
            else np.ones(3)
        )
        """Colour gain of each channel this episode (exposure x white balance)."""
        self.scale_offset = self.rng.uniform(-s.offset, s.offset) if not noise.ideal else 0.0
        self.scale_drift = self.rng.uniform(-s.drift, s.drift) if not noise.ideal else 0.0

    def draws(self, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """This frame's draws (:meth:`frame`'s, in its order) for the whole image's noiseless
        ``depth`` (h, w) [m]: depth normals (one per pixel with a reading), hole uniforms
        (h, w), colour normals (h, w, 3) float64; None for a camera without noise. They
        depend on the depth alone: a simulator draws them while the colours are drawn."""
        if self.noise.camera == CameraNoise():
            return None
        rng = self.rng
        valid = np.isfinite(depth) & (depth > 0)
        normals = rng.standard_normal(np.count_nonzero(valid))
        return normals, rng.random(depth.shape), rng.standard_normal((*depth.shape, 3))

    def frame(
        self,
        frame: CameraFrame,
        region: tuple[int, int, int, int] | None = None,
        draws: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> CameraFrame:
        """The frame as the camera would give it: noisy depth with holes, noisy colour.

        ``region`` ``(v0, v1, u0, u1)``: only rows ``v0:v1`` and columns ``u0:u1`` are
        read, the rest of the image holds no reading (depth 0, black). The generator draws
        for the whole frame all the same (below): those pixels are the whole frame's to the
        bit, and every later draw is as without ``region``. ``frame.depth`` must then hold
        the whole image's readings (which pixels have one, and the window's neighbours for
        its edges); ``frame.rgb`` only the window's. ``draws``: :meth:`draws` of this
        frame's depth, made already (else made here).

        Draws per frame, in this order: one standard normal per pixel with a reading (finite,
        > 0) of the whole image in row-major order (depth), one uniform per pixel (holes),
        three standard normals per pixel (colour, row-major, channels last).
        """
        c = self.noise.camera
        if c == CameraNoise():
            return frame
        h, w = frame.depth.shape
        v0, v1, u0, u1 = (0, h, 0, w) if region is None else region
        full = frame.depth
        valid = np.isfinite(full) & (full > 0)
        made = draws if draws is not None else self.draws(full)
        assert made is not None  # a camera with noise draws
        normals, holes, grain_whole = made
        depth = full[v0:v1, u0:u1].astype(np.float32, copy=True)
        seen_at = valid[v0:v1, u0:u1]
        if region is not None:
            # The window's readings' places in those draws: the readings before its rows,
            # then a running count along its rows (full width: the row-major order).
            rank = np.cumsum(valid[v0:v1], axis=None).reshape(v1 - v0, w)[:, u0:u1]
            rank += np.count_nonzero(valid[:v0]) - 1
            normals = normals[rank[seen_at]]
        seen = depth[seen_at]  # sigma only where a reading is: the same float32 arithmetic
        sigma = c.depth_a + c.depth_b * (seen - c.depth_z0) ** 2
        depth[seen_at] = seen + (normals * sigma).astype(np.float32)
        # Colour of whole rows: matmul runs its kernel image row by image row, and each
        # window pixel's luma is then the whole image's to the bit.
        rows = frame.rgb[v0:v1].astype(np.float32) / 255.0
        luma = (rows @ np.array([0.299, 0.587, 0.114], dtype=np.float32))[:, u0:u1]
        kind = self._jump(full, (v0, v1, u0, u1)).view(np.uint8)
        kind += 2 * (luma < c.dark_luma).view(np.uint8)
        # A pixel's dropout probability: the largest of those its kinds have, looked up by
        # kind (edge, dark) instead of two full-frame maxima; float64, as drawn against.
        anywhere = float(np.float32(c.dropout))
        edge, dark = max(anywhere, c.edge_dropout), max(anywhere, c.dark_dropout)
        p = np.array([anywhere, edge, dark, max(edge, dark)])
        depth[holes[v0:v1, u0:u1] < p[kind]] = 0.0
        depth[depth < 0] = 0.0
        rgb = rows if region is None else rows[:, u0:u1].copy()
        rgb *= self.gain.astype(np.float32)
        grain = grain_whole[v0:v1, u0:u1].astype(np.float32)
        grain *= c.colour_sigma
        rgb += grain
        rgb *= 255.0
        out = np.clip(np.rint(rgb, out=rgb), 0, 255, out=rgb).astype(np.uint8)
        if region is None:
            return replace(frame, rgb=out, depth=depth)
        whole_rgb = np.zeros((h, w, 3), dtype=np.uint8)
        whole_rgb[v0:v1, u0:u1] = out
        whole_depth = np.zeros((h, w), dtype=np.float32)
        whole_depth[v0:v1, u0:u1] = depth
        return replace(frame, rgb=whole_rgb, depth=whole_depth)

    def _jump(self, depth: np.ndarray, region: tuple[int, int, int, int]) -> np.ndarray:
        """The depth edges (bool) in ``region``'s window of the noiseless ``depth`` (h, w)
        [m]: a jump over ``edge_jump`` to a 4-neighbour."""
        c = self.noise.camera
        h, w = depth.shape
        v0, v1, u0, u1 = region
        # The window grown by a pixel each way (within the image): its edges' neighbours.
        a0, a1, b0, b1 = max(v0 - 1, 0), min(v1 + 1, h), max(u0 - 1, 0), min(u1 + 1, w)
        near = depth[a0:a1, b0:b1]
        jump = np.zeros(near.shape, dtype=bool)
        with np.errstate(invalid="ignore"):  # inf - inf beside a hole: nan, not a jump
            dz_x = np.abs(np.diff(near, axis=1)) > c.edge_jump
            dz_y = np.abs(np.diff(near, axis=0)) > c.edge_jump
        jump[:, 1:] |= dz_x
        jump[:, :-1] |= dz_x
        jump[1:, :] |= dz_y
        jump[:-1, :] |= dz_y
        return jump[v0 - a0 : v1 - a0, u0 - b0 : u1 - b0]

    def weight(self, t: float, weight: float) -> float:
        """A scale reading [kg] at time ``t`` [s]."""
        s = self.noise.scale
        if s == ScaleNoise():
            return weight
        return float(
            weight + self.scale_offset + self.scale_drift * t + self.rng.normal(0.0, s.sigma)
        )

    def scan(self, scan: LidarReading) -> LidarReading:
        """A lidar scan with range noise and lost beams."""
        n = self.noise.lidar
        if n == LidarNoise():
            return scan
        ranges = np.asarray(scan.ranges, dtype=float).copy()
        hit = np.isfinite(ranges)
        sigma = n.sigma + n.sigma_rel * ranges[hit]
        ranges[hit] = np.maximum(ranges[hit] + self.rng.standard_normal(int(hit.sum())) * sigma, 0)
        ranges[self.rng.random(ranges.shape) < n.dropout] = np.inf
        ranges[ranges > scan.range_max] = np.inf
        return replace(scan, ranges=ranges)
