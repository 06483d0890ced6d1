"""Text rendering of an SMC tree for the terminal (``smc compile`` prints it)."""

from __future__ import annotations

import colorsys

import numpy as np
from rich.console import Console
from rich.tree import Tree as RichTree

from smccli.perception import Cluster, PerceptionParams
from smccli.smc import Smc
from smccli.tree import ROOT, Tree


HUE_NAMES = ((0.04, "red"), (0.11, "orange"), (0.19, "yellow"), (0.45, "green"),
             (0.54, "cyan"), (0.72, "blue"), (0.85, "purple"), (0.96, "pink"), (1.01, "red"))


def dominant_colour(cluster: Cluster, params: PerceptionParams) -> tuple[str, tuple[int, int, int]]:
    """Name and RGB (0-255) of a cluster's dominant colour, read off its histogram.

    The histogram is ``hue x saturation`` bins for coloured pixels then brightness bins for
    achromatic ones (:mod:`smccli.perception.histogram`).
    """
    h = np.asarray(cluster.histogram, dtype=float)
    nh, ns, nv = params.hue_bins, params.sat_bins, params.val_bins
    chroma, achrom = h[: nh * ns].reshape(nh, ns), h[nh * ns : nh * ns + nv]
    if achrom.sum() >= chroma.sum():
        v = (int(np.argmax(achrom)) + 0.5) / nv
        name = "black" if v < 0.34 else ("grey" if v < 0.67 else "white")
        g = int(255 * v)
        return name, (g, g, g)
    per_hue = chroma.sum(axis=1)
    hue = (int(np.argmax(per_hue)) + 0.5) / nh
    sat = (float(np.argmax(chroma[int(np.argmax(per_hue))])) + 0.5) / ns
    name = next(n for edge, n in HUE_NAMES if hue < edge)
    r, g, b = colorsys.hsv_to_rgb(hue, max(sat, 0.5), 0.9)
    return name, (int(255 * r), int(255 * g), int(255 * b))


def describe_perception(smc: Smc, params: PerceptionParams | None = None) -> str:
    """One-line summary of an SMC's salient perceptions."""
    parts = []
    c = smc.perception.cluster
    if c is not None:
        ext = "x".join(f"{100 * e:.0f}" for e in c.extents)
        parts.append(f"{dominant_colour(c, params or PerceptionParams())[0]} object {ext} cm at "
                     f"({c.centroid[0]:.2f}, {c.centroid[1]:.2f})")
    if smc.perception.weight is not None:
        parts.append(f"weight {1000 * smc.perception.weight:.0f} g")
    return ", ".join(parts) or "nothing localized"


def describe_action(smc: Smc) -> str:
    """One-line summary of an SMC's action."""
    a = smc.action
    g = a.goal
    where = "rel. object" if a.goal_frame == "object" else "world"
    return (f"{a.event} | goal ({g[0]:+.3f}, {g[1]:+.3f}, {g[2]:+.3f}) m {where}, "
            f"{a.dmp.duration:.1f} s")


def print_tree(tree: Tree, console: Console) -> None:
    """Print nodes and edges as an indented tree."""
    root = RichTree(f"[bold]{ROOT}[/] (root)")
    stack = [(ROOT, root)]
    while stack:
        node, branch = stack.pop()
        added = []
        for e in tree.children(node):
            srcs = ", ".join(f"{s.log}@{s.t0:.1f}-{s.t1:.1f}s" for s in e.sources)
            child = branch.add(f"[cyan]{e.id}[/] -> [bold]{e.child}[/]  "
                               f"{describe_perception(e.smc, tree.params.perception)}  ||  {describe_action(e.smc)}  "
                               f"[dim]support {e.support}: {srcs}[/]")
            added.append((e.child, child))
        stack.extend(reversed(added))
    console.print(root)
