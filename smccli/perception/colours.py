"""Colours of perceived objects, read off their histograms, for people (tree print, Rerun).

The hue is estimated from the bin masses, not taken as the heaviest bin's centre: the
histogram spreads each pixel's vote linearly over the two nearest hue bins
(:mod:`smccli.perception.histogram`), so the mass-weighted mean of the heaviest bin's and
its neighbours' centres gives back the hue of a one-coloured object exactly. The bin
centre alone sat 15 deg off: with 12 bins the first is centred at 15 deg, on the
red/orange border, and a red cube (0 deg) and an orange one (25 deg) both fell in it
(issue 26). Names then go to the nearest of the named hues (:data:`NAMED_HUES`).
"""

from __future__ import annotations

import colorsys

import numpy as np

NAMED_HUES = (
    ("red", 0.0),
    ("orange", 30.0),
    ("yellow", 60.0),
    ("green", 120.0),
    ("cyan", 180.0),
    ("blue", 235.0),
    ("purple", 275.0),
    ("pink", 320.0),
)
"""Each name's hue [deg]; a hue takes the nearest one's name (red/orange at 15 deg,
orange/yellow at 45, yellow/green at 90, ..., pink/red at 340)."""
CHROMATIC = 0.25
"""Below this HSV saturation a colour is white, grey or black."""


def dominant_hue(histogram: np.ndarray, hue_bins: int, sat_bins: int) -> float:
    """Hue [deg, 0-360) of the heaviest hue bin of a histogram's chromatic part, refined by
    its two neighbours' masses (see the module)."""
    n_c = hue_bins * sat_bins
    per_hue = np.asarray(histogram, dtype=float)[:n_c].reshape(hue_bins, sat_bins).sum(axis=1)
    k = int(np.argmax(per_hue))
    offsets = np.array([-1, 0, 1])
    mass = per_hue[(k + offsets) % hue_bins]
    centre = k + 0.5 + float(mass @ offsets) / max(float(mass.sum()), 1e-12)
    return (centre / hue_bins * 360.0) % 360.0


def dominant_rgb(
    histogram: np.ndarray, hue_bins: int = 12, sat_bins: int = 3, val_bins: int = 3
) -> tuple[int, int, int]:
    """RGB of a cluster histogram's dominant colour (layout:
    :mod:`smccli.perception.histogram`): its hue (:func:`dominant_hue`) when the chromatic
    bins hold most of the mass, else its heaviest brightness bin's grey."""
    h = np.asarray(histogram, dtype=float)
    n_c = hue_bins * sat_bins
    if h.shape != (n_c + val_bins,) or not h.sum() > 0:
        return (160, 160, 160)
    if h[:n_c].sum() >= h[n_c:].sum():
        hs = h[:n_c].reshape(hue_bins, sat_bins)
        row = hs[int(np.argmax(hs.sum(axis=1)))]
        sat = (float(np.dot(row, np.arange(sat_bins) + 0.5)) / max(row.sum(), 1e-12)) / sat_bins
        hue = dominant_hue(h, hue_bins, sat_bins) / 360.0
        r, g, b = colorsys.hsv_to_rgb(hue, max(sat, 0.45), 0.9)
    else:
        # The brightness bin's centre: dark, mid, bright read black, grey, white.
        r = g = b = (int(np.argmax(h[n_c:])) + 0.5) / val_bins
    return (int(255 * r), int(255 * g), int(255 * b))


def colour_name(rgb: tuple[int, int, int]) -> str:
    """A plain colour word for ``rgb``: the nearest of :data:`NAMED_HUES`, or white / grey
    / black for achromatic colours."""
    h, s, v = colorsys.rgb_to_hsv(*(c / 255 for c in rgb))
    if s < CHROMATIC:
        return "white" if v > 0.75 else "grey" if v > 0.3 else "black"
    deg = h * 360.0
    return min(NAMED_HUES, key=lambda nh: abs((deg - nh[1] + 180.0) % 360.0 - 180.0))[0]
