"""Colours of perceived objects, read off their histograms, for people (tree print, Rerun)."""

from __future__ import annotations

import colorsys

import numpy as np


def dominant_rgb(
    histogram: np.ndarray, hue_bins: int = 12, sat_bins: int = 3, val_bins: int = 3
) -> tuple[int, int, int]:
    """RGB of a cluster histogram's heaviest bin (layout: :mod:`smccli.perception.histogram`).

    Chromatic bins [hue x saturation] come first, then the achromatic brightness bins.
    """
    h = np.asarray(histogram, dtype=float)
    n_c = hue_bins * sat_bins
    if h.shape != (n_c + val_bins,) or not h.sum() > 0:
        return (160, 160, 160)
    if h[:n_c].sum() >= h[n_c:].sum():
        hs = h[:n_c].reshape(hue_bins, sat_bins)
        hue = (int(np.argmax(hs.sum(axis=1))) + 0.5) / hue_bins
        row = hs[int(np.argmax(hs.sum(axis=1)))]
        sat = (float(np.dot(row, np.arange(sat_bins) + 0.5)) / max(row.sum(), 1e-12)) / sat_bins
        r, g, b = colorsys.hsv_to_rgb(hue, max(sat, 0.45), 0.9)
    else:
        v = (int(np.argmax(h[n_c:])) + 0.5) / val_bins
        r = g = b = 0.25 + 0.7 * v
    return (int(255 * r), int(255 * g), int(255 * b))


def colour_name(rgb: tuple[int, int, int]) -> str:
    """A plain colour word for ``rgb``: red, orange, yellow, green, cyan, blue, purple,
    pink, or white / grey / black for achromatic colours."""
    h, s, v = colorsys.rgb_to_hsv(*(c / 255 for c in rgb))
    if s < 0.25:
        return "white" if v > 0.75 else "grey" if v > 0.3 else "black"
    deg = h * 360
    for limit, name in (
        (15, "red"),
        (45, "orange"),
        (70, "yellow"),
        (165, "green"),
        (195, "cyan"),
        (255, "blue"),
        (290, "purple"),
        (340, "pink"),
    ):
        if deg < limit:
            return name
    return "red"
