"""The room's colours as a simple intrinsic perception (SI, eq. 9; paper 4.2): the colour
histogram of whole camera frames and its distance.

The histogram is the object clusters' (:mod:`smccli.perception.histogram`): hue x
saturation with soft bins for coloured pixels, brightness for grey ones. Measured in
MuJoCo (docs/design.md section 9): HSV with soft bins moves by 0.005 (-ln BC) for a 0.4 m /
20 deg jitter where RGB moves by 0.34; a 60 deg turn moves it by 0.12, a panorama of 4
views by 0.08; differently coloured rooms are > 0.6 apart. A poster must fill >= 5 % of the
frame to move a whole-frame histogram.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from smccli.perception.histogram import d_histogram, hsv_histogram
from smccli.perception.params import PerceptionParams


def room_histogram(
    frames: np.ndarray | Sequence[np.ndarray],
    params: PerceptionParams | None = None,
    *,
    stride: int = 1,
) -> np.ndarray:
    """Colour histogram of whole RGB frames, shape (histogram_size,), sums to 1.

    ``frames``: one image (H, W, 3) uint8 or several (a panorama: the pixels of all views
    are pooled: a 60 deg turn then moves the histogram by 0.08 instead of 0.12). ``stride``
    keeps every stride-th row and column, to bin fewer pixels.
    """
    params = params or PerceptionParams()
    if stride < 1:
        raise ValueError(f"room_histogram: stride must be >= 1, got {stride}")
    views = [frames] if isinstance(frames, np.ndarray) and frames.ndim == 3 else list(frames)
    if not views:
        raise ValueError("room_histogram: no frames")
    pixels = []
    for v in views:
        img = np.asarray(v)
        if img.ndim != 3 or img.shape[2] != 3:
            raise ValueError(f"room_histogram: expected (H, W, 3) RGB frames, got {img.shape}")
        pixels.append(img[::stride, ::stride].reshape(-1, 3))
    return hsv_histogram(np.concatenate(pixels), params)


def d_room(a: np.ndarray, b: np.ndarray, params: PerceptionParams | None = None) -> float:
    """d_P of two room histograms (eq. 9): -ln BC over ``hist_scale``, as the colour term
    of :func:`~smccli.perception.d_cluster`.

    With hist_scale = 3.5: a 60 deg turn scores 0.034 (0.023 with a 4-view panorama),
    leaving most of T_hP = 0.1 to the scan's distance in the sum of eq. 26; differently
    coloured rooms score > 0.17 on their own.
    """
    params = params or PerceptionParams()
    return d_histogram(a, b) / params.hist_scale
