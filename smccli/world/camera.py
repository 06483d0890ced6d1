"""The sensor camera's renderer: RGB and metric depth of a MuJoCo camera, the whole image
or a window of it (:class:`CameraRenderer`, used by :meth:`smccli.world.sim.Sim.render_camera`).
"""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import numpy as np
from OpenGL import platform as gl_platform  # the GL library of mujoco's context (glFlush)

from smccli.world.render_mesh import render_model
from smccli.world.scene import HIDDEN_GROUP


class CameraRenderer:
    """Renders camera ``cam_id`` of ``model`` at ``height`` x ``width`` pixels: a lit pass
    for colour, a segmented pass for depth (mujoco.Renderer's passes), meshes of more than
    :data:`~smccli.world.render_mesh.RENDER_FACES` triangles drawn simplified. Its GL
    context is built at the first frame."""

    def __init__(self, model: mujoco.MjModel, cam_id: int, height: int, width: int) -> None:
        self.model = model
        self.cam_id = cam_id
        self.height = height
        self.width = width
        self._renderer: mujoco.Renderer | None = None
        self._pending: Callable[[], np.ndarray] | None = None
        """The colour pass drawn and not read yet (:meth:`render`): read before any other."""

    @property
    def near(self) -> float:
        """The near clipping distance [m]: no depth reading is nearer."""
        return float(self.model.vis.map.znear * self.model.stat.extent)

    def start(self, data: mujoco.MjData) -> None:
        """Build the renderer and render one frame, discarded, unless it runs already."""
        if self._renderer is None:
            self.render(data)[0]()

    def close(self) -> None:
        """Free the GL context (a colour pass not read yet is read first)."""
        self._settle()
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def _option(self) -> mujoco.MjvOption:
        """What the camera sees: every geom group but the hidden one, no sites."""
        opt = mujoco.MjvOption()
        opt.geomgroup[:] = 1
        opt.geomgroup[HIDDEN_GROUP] = 0  # the teleop marker, parked objects: not the world's
        opt.sitegroup[:] = 0  # sites (the POI marker) are not seen by a real camera
        return opt

    def _settle(self) -> None:
        """Read a colour pass still in the framebuffer, before anything else draws there."""
        if self._pending is not None:
            self._pending()

    def _ready(self) -> mujoco.Renderer:
        self._settle()
        if self._renderer is None:
            # The physics' data draws in a copy whose large meshes are simplified.
            drawn = render_model(self.model)
            self._renderer = mujoco.Renderer(drawn, self.height, self.width)
            self._renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
            self._renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
        return self._renderer

    def render(self, data: mujoco.MjData) -> tuple[Callable[[], np.ndarray], np.ndarray]:
        """The whole image: a function that returns its RGB (h, w, 3) uint8, and its depth
        (h, w) float32 [m], 0 where nothing is seen.

        The depth pass is drawn and read first; the lit pass is then drawn without
        waiting for it (queued and flushed: Mesa's rasteriser threads draw it while the
        caller works), and the function reads it back, waiting for it if it is not done
        (a :class:`~smccli.world.sensors.DrawingFrame`'s ``fetch``). Anything else this
        renderer draws reads it first. The pixels are the passes' own, as
        ``mujoco.Renderer.render`` reads them.
        """
        depth = self._depth(data)
        return self._colour_later(data, None), depth

    def _colour_later(
        self, data: mujoco.MjData, region: tuple[int, int, int, int] | None
    ) -> Callable[[], np.ndarray]:
        """Draw the lit pass of the whole image (``region`` None) or of a window, without
        waiting for it; the function returned reads it back once (RGB (h, w, 3) uint8,
        black outside the window) and is this renderer's pending read until then."""
        black = np.zeros((self.height, self.width, 3), dtype=np.uint8)
        if region is None:
            r = self._ready()
            r.update_scene(data, camera=self.cam_id, scene_option=self._option())
            r._gl_context.make_current()
            mujoco.mjr_render(r._rect, r.scene, r._mjr_context)
            rect, (v0, v1, u0, u1) = r._rect, (0, self.height, 0, self.width)
        else:
            v0, v1, u0, u1 = region
            if v1 <= v0 or u1 <= u0:  # an empty window: nothing to draw
                return lambda: black
            r, rect = self._draw_window(data, region, segment=False)
        gl_platform.PLATFORM.GL.glFlush()  # start drawing now, not at the read
        rgb: list[np.ndarray] = []

        def fetch() -> np.ndarray:
            if not rgb:
                self._pending = None
                black[v0:v1, u0:u1] = self._read_window(r, rect, segment=False)
                rgb.append(black)
            return rgb[0]

        self._pending = fetch
        return fetch

    def _depth(self, data: mujoco.MjData) -> np.ndarray:
        """The whole image's depth (h, w) float32 [m], 0 where nothing is seen."""
        r = self._ready()
        # Depth is a second pass: mujoco.Renderer draws it with segmentation colours, and
        # its depth then differs from the lit pass's by about 1 mm at the table;
        # logs hold the segmented pass's, so replay must perceive the same.
        r.enable_depth_rendering()
        r.update_scene(data, camera=self.cam_id, scene_option=self._option())
        # mujoco.Renderer already linearises the depth buffer to metres along the optical
        # axis (z-depth, not ray length), which is what CameraFrame wants.
        depth = r.render().astype(np.float32)
        r.disable_depth_rendering()
        far = self.model.vis.map.zfar * self.model.stat.extent
        depth[depth >= 0.999 * far] = 0.0
        return depth

    def region(
        self, data: mujoco.MjData, region: tuple[int, int, int, int], colour: bool = True
    ) -> tuple[np.ndarray, np.ndarray]:
        """As :meth:`render`, drawing only rows ``v0:v1`` and columns ``u0:u1`` of
        ``region``; the rest holds no reading (depth 0, black). Without ``colour`` only the
        depth pass is drawn and the image stays black (half the time).

        The GL frustum is cut to that window and drawn in a viewport of its size: the same
        pixel rays at a fraction of the fill (llvmpipe's cost: about a third of a frame's
        time for a look's window). Colours come out as the whole frame's but for a rare
        pixel on an edge (another projection matrix: one pixel of bench_pick's window
        ``(29, 196, 30, 253)`` at the nominal layout); depths may differ in the last bits
        (a micrometre). The two passes and the depth linearisation are mujoco.Renderer's,
        with its scene and GL context (its ``render`` always draws the whole viewport).
        """
        h, w = self.height, self.width
        v0, v1, u0, u1 = region
        rgb = np.zeros((h, w, 3), dtype=np.uint8)
        depth = np.zeros((h, w), dtype=np.float32)
        if v1 > v0 and u1 > u0:
            if colour:
                rgb[v0:v1, u0:u1] = self._window(data, region, segment=False)
            depth[v0:v1, u0:u1] = self._metric(self._window(data, region, segment=True))
        return rgb, depth

    def colour_region(
        self, data: mujoco.MjData, region: tuple[int, int, int, int]
    ) -> tuple[Callable[[], np.ndarray], np.ndarray]:
        """As :meth:`render`, the colours of :meth:`region`'s window alone (black
        elsewhere), the whole image's depth to the bit: for a camera whose noise depends on
        which pixels have a reading and on the depth edges (the lit pass is about 70 % of a
        frame's time, 7 of 10 ms at 320x240; the window's about 2.7)."""
        depth = self._depth(data)
        return self._colour_later(data, region), depth

    def _window(
        self, data: mujoco.MjData, region: tuple[int, int, int, int], segment: bool
    ) -> np.ndarray:
        """One pass drawn in the (non-empty) window of :meth:`region`, top row first: RGB
        (v1 - v0, u1 - u0, 3) uint8 lit, or the segmented pass's raw depth buffer
        (v1 - v0, u1 - u0) float32."""
        r, rect = self._draw_window(data, region, segment)
        return self._read_window(r, rect, segment)

    def _draw_window(
        self, data: mujoco.MjData, region: tuple[int, int, int, int], segment: bool
    ) -> tuple[mujoco.Renderer, mujoco.MjrRect]:
        """Draw one pass of :meth:`_window` (not read yet): the renderer and the viewport."""
        h, w = self.height, self.width
        v0, v1, u0, u1 = region
        r = self._ready()
        r._gl_context.make_current()
        scene, ctx = r.scene, r._mjr_context
        rect = mujoco.MjrRect(0, 0, u1 - u0, v1 - v0)
        flags = scene.flags.copy()
        r.update_scene(data, camera=self.cam_id, scene_option=self._option())
        for c in scene.camera:  # GL rows count up from the image's bottom
            pixel = (c.frustum_top - c.frustum_bottom) / h
            c.frustum_center += (0.5 * (u0 + u1) - 0.5 * w) * pixel
            c.frustum_bottom, c.frustum_top = (
                c.frustum_bottom + (h - v1) * pixel,
                c.frustum_bottom + (h - v0) * pixel,
            )
        scene.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = segment
        scene.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = segment
        mujoco.mjr_render(rect, scene, ctx)
        np.copyto(scene.flags, flags)
        return r, rect

    @staticmethod
    def _read_window(r: mujoco.Renderer, rect: mujoco.MjrRect, segment: bool) -> np.ndarray:
        """Read the pass just drawn in ``rect``, top row first (:meth:`_window`)."""
        r._gl_context.make_current()
        if segment:
            out = np.empty((rect.height, rect.width), dtype=np.float32)
            mujoco.mjr_readPixels(None, out, rect, r._mjr_context)
        else:
            out = np.empty((rect.height, rect.width, 3), dtype=np.uint8)
            mujoco.mjr_readPixels(out, None, rect, r._mjr_context)
        return np.flipud(out)

    def _metric(self, buffer: np.ndarray) -> np.ndarray:
        """A reversed-Z depth buffer in metres along the optical axis, float32, 0 where
        nothing is seen: mujoco.Renderer's arithmetic, in its precisions."""
        extent = self.model.stat.extent
        znear = np.float32(self.model.vis.map.znear * extent)
        zfar = np.float32(self.model.vis.map.zfar * extent)
        c_coef = np.float32(-0.5) * (-(zfar + znear) / (zfar - znear)) - np.float32(0.5)
        d_coef = np.float32(-0.5) * (-(np.float32(2) * zfar * znear) / (zfar - znear))
        depth = (d_coef / (buffer.astype(np.float64) + c_coef)).astype(np.float32)
        depth[depth >= 0.999 * self.model.vis.map.zfar * extent] = 0.0
        return depth
