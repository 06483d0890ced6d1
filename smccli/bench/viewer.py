"""``smc inspect --serve`` in a real browser: Debian's Chromium driven by Playwright.

Used by the browser test (tests/test_inspect.py) and for the viewer screenshots (README,
docs/inspect.md):
``python -m smccli.bench.viewer`` (``make viewer-shots``) compiles the sample trees, serves
each with its logs, waits until the page has drawn them and writes
``docs/img/viewer_<scene>.png``.

Chromium renders WebGL on the CPU (SwiftShader; ``&renderer=webgl`` in the URL picks
Rerun's WebGL backend). It runs headless, with no sandbox (root in CI), and without the
background networking this closed machine refuses. Pixels are read from screenshots of a
1600 x 1000 page, where the blueprint puts each view at a known fraction of the page.
"""

from __future__ import annotations

import io
import os
import re
import select
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

CHROMIUM = os.environ.get("SMC_CHROMIUM", "/usr/bin/chromium")
"""The browser (Debian's ``chromium``, installed by the Makefile)."""
CHROMIUM_ARGS = (
    "--headless=new",
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
)
VIEWPORT = (1600, 1000)
"""Page size [px]; the regions below are fractions of it."""


@dataclass(frozen=True, slots=True)
class Region:
    """A view's place on the page, as fractions of its width and height."""

    x0: float
    x1: float
    y0: float
    y1: float

    def crop(self, image: np.ndarray) -> np.ndarray:
        h, w = image.shape[:2]
        return image[int(self.y0 * h) : int(self.y1 * h), int(self.x0 * w) : int(self.x1 * w)]


# Measured on a 1600 x 1000 page with smc's blueprint (sources panel open, selection panel
# collapsed), a few pixels inside each view's frame, below its title bar.
GRAPH = Region(0.13, 0.56, 0.07, 0.52)
WORLD = Region(0.57, 0.99, 0.07, 0.52)
CAMERA = Region(0.565, 0.705, 0.56, 0.84)


@dataclass(frozen=True, slots=True)
class Served:
    """A running ``smc inspect --serve``."""

    proc: subprocess.Popen[str]
    viewer: str
    """The viewer address it printed."""
    data: str
    """The data (gRPC) address it printed."""


@contextmanager
def serving(
    tree: Path,
    logs: Sequence[Path],
    *,
    port: int,
    grpc_port: int | None = None,
    timeout: float = 300.0,
) -> Iterator[Served]:
    """Run ``smc inspect TREE LOGS --serve`` until the block ends, then Ctrl-C it."""
    cmd = [sys.executable, "-m", "smccli.cli", "inspect", str(tree), *map(str, logs)]
    cmd += ["--serve", "--port", str(port)]
    if grpc_port is not None:
        cmd += ["--grpc-port", str(grpc_port)]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1
    )
    try:
        seen, deadline = "", time.monotonic() + timeout
        # both lines whole: a read may end inside one
        while not (re.search(r"viewer: \S+\n", seen) and re.search(r"data: +\S+\n", seen)):
            if proc.poll() is not None:
                raise RuntimeError(f"smc inspect --serve exited: {proc.communicate()[1]}")
            if time.monotonic() > deadline:
                raise TimeoutError(f"no addresses printed within {timeout:.0f} s: {seen!r}")
            assert proc.stdout is not None
            ready, _, _ = select.select([proc.stdout], [], [], 1.0)
            if ready:  # the raw pipe: readline() would keep a second line in its buffer,
                # which select does not see, and wait for output that already came
                seen += os.read(proc.stdout.fileno(), 65536).decode()
        viewer = re.search(r"viewer: (\S+)", seen)
        data = re.search(r"data: +(\S+)", seen)
        assert viewer is not None and data is not None
        yield Served(proc, viewer.group(1), data.group(1))
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(60)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


@contextmanager
def browser_page() -> Iterator[Any]:
    """A Playwright page in headless Chromium, closed (browser and driver) on exit."""
    from playwright.sync_api import sync_playwright

    if not Path(CHROMIUM).is_file():
        raise FileNotFoundError(f"{CHROMIUM}: no Chromium (make installs Debian's chromium)")
    with tempfile.TemporaryDirectory(prefix="smc-chromium-") as profile:
        with sync_playwright() as pw:
            context = pw.chromium.launch_persistent_context(
                profile,
                executable_path=CHROMIUM,
                args=list(CHROMIUM_ARGS),
                viewport={"width": VIEWPORT[0], "height": VIEWPORT[1]},
                headless=True,
            )
            try:
                yield context.pages[0] if context.pages else context.new_page()
            finally:
                context.close()


def webgl_url(viewer: str) -> str:
    """The viewer address with Rerun's WebGL renderer chosen (no WebGPU here)."""
    return viewer + ("&" if "?" in viewer else "?") + "renderer=webgl"


def screenshot(page: Any) -> np.ndarray:
    """The page as an RGB array, shape (h, w, 3) uint8."""
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB"))


def wait_for(
    page: Any, drawn: Callable[[np.ndarray], bool], timeout: float, period: float = 2.0
) -> np.ndarray:
    """Screenshots every ``period`` s until ``drawn(image)``; the image that passed.

    TimeoutError after ``timeout`` s with the last screenshot saved next to the temp dir.
    """
    deadline = time.monotonic() + timeout
    while True:
        image = screenshot(page)
        if drawn(image):
            return image
        if time.monotonic() > deadline:
            from PIL import Image

            last = Path(tempfile.gettempdir()) / "smc-viewer-timeout.png"
            Image.fromarray(image).save(last)
            raise TimeoutError(f"the page did not draw within {timeout:.0f} s (last: {last})")
        time.sleep(period)


def colour_pixels(image: np.ndarray, rgb: Sequence[int], tol: int = 12) -> int:
    """How many pixels are within ``tol`` of ``rgb`` in every channel."""
    diff = np.abs(image.astype(int) - np.asarray(rgb, dtype=int)[None, None, :])
    return int(np.count_nonzero(diff.max(axis=2) <= tol))


def image_in_panel(panel: np.ndarray) -> np.ndarray | None:
    """The picture shown in a 2D view: the box of pixels unlike the view's background (its
    corner colour), or None when the view is empty."""
    bg = panel[2, 2].astype(int)
    differs = np.abs(panel.astype(int) - bg[None, None, :]).max(axis=2) > 12
    rows = np.flatnonzero(differs.mean(axis=1) > 0.5)
    cols = np.flatnonzero(differs.mean(axis=0) > 0.5)
    if len(rows) < 20 or len(cols) < 20:
        return None
    return panel[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]


def image_distance(shown: np.ndarray, frame: np.ndarray) -> float:
    """Mean absolute difference [0-255] between a shown picture and a frame scaled to it."""
    from PIL import Image

    h, w = shown.shape[:2]
    scaled = np.asarray(Image.fromarray(frame).resize((w, h), Image.Resampling.BILINEAR))
    return float(np.abs(shown.astype(float) - scaled.astype(float)).mean())


# --- screenshots (README, docs/inspect.md) --------------------------------------------------------


def page_drawn(tree: Any, frame: np.ndarray | None = None) -> Callable[[np.ndarray], bool]:
    """Whether a screenshot shows ``tree``: every swatch colour in the graph view, a branch
    colour in the 3D view; with ``frame`` (an RGB camera frame), the camera view shows a
    picture within 20 (mean, of 255) of it."""
    from smccli.inspect.labels import branch_colours, swatch_rgb

    colours = branch_colours(tree)
    swatches = {swatch_rgb(e, tree, colours[e.id]) for e in tree.edges}

    def drawn(image: np.ndarray) -> bool:
        graph, world = GRAPH.crop(image), WORLD.crop(image)
        if not all(colour_pixels(graph, c, 10) >= 6 for c in swatches):
            return False
        if not any(colour_pixels(world, c, 10) >= 20 for c in set(colours.values())):
            return False
        if frame is None:
            return True
        shown = image_in_panel(CAMERA.crop(image))
        return shown is not None and image_distance(shown, frame) < 20

    return drawn


def main() -> None:
    """Screenshots of the sample trees in the web viewer -> docs/img/viewer_<scene>.png."""
    from PIL import Image

    from smccli.inspect.serve import free_port
    from smccli.learn.compile import compile_logs
    from smccli.learn.tree import load_tree
    from smccli.logs import read_log

    repo = Path(__file__).resolve().parents[2]
    samples = repo / "sample_logs"
    out_dir = repo / "docs" / "img"
    shots = {"pick_place": None, "weigh_sort": None, "rooms": None}
    with tempfile.TemporaryDirectory(prefix="smc-shots-") as tmp:
        for scene in shots:
            logs = sorted((samples / scene).glob("*.mcap"))
            tree_path = Path(tmp) / f"{scene}.json"
            compile_logs(logs, tree_path)
            drawn = page_drawn(load_tree(tree_path), read_log(logs[0]).frames[-1].rgb)
            with serving(tree_path, logs, port=free_port()) as served:
                with browser_page() as page:
                    page.goto(webgl_url(served.viewer), timeout=120_000)
                    wait_for(page, drawn, timeout=600)
                    time.sleep(5.0)  # let the 3D view settle its last frames
                    image = screenshot(page)
            out = out_dir / f"viewer_{scene}.png"
            Image.fromarray(image).save(out, optimize=True)
            print(f"wrote {out.relative_to(repo)}")


if __name__ == "__main__":
    main()
