"""Colours and labels of inspect's recordings: the palette, the colours of branches,
objects and rooms, and the words that describe an SMC in the graph and the table."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from smccli.learn.tree import ROOT, Edge, Tree
from smccli.perception.colours import colour_name, dominant_rgb

if TYPE_CHECKING:
    from smccli.perception.clusters import Cluster

Rgb = tuple[int, int, int]
"""A colour, 0-255 per channel."""

PALETTE: list[Rgb] = [
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
]
HIGHLIGHT: Rgb = (255, 215, 0)
TEXT_RGB: Rgb = (118, 118, 118)
"""Graph text: contrast about 4.5:1 on both the light and the dark theme."""
SWATCH_GLYPH = "\u25a0"
"""A swatch in the graph: a square in the object's colour."""
PATH_RGB: Rgb = (128, 128, 128)
"""The path a log took (neutral: the branch colours are the demonstrated actions')."""
SCAN_RGB: Rgb = (230, 70, 50)
"""Lidar scans and the lidar's pose."""


def cluster_rgb(cluster: Cluster, tree: Tree) -> Rgb:
    """Dominant colour of an object cluster (binned as the tree's perception)."""
    p = tree.params.perception
    return dominant_rgb(cluster.histogram, p.hue_bins, p.sat_bins, p.val_bins)


def cluster_name(cluster: Cluster, tree: Tree) -> str:
    """An object cluster's colour in a word."""
    return colour_name(cluster_rgb(cluster, tree))


def swatch_rgb(edge: Edge, tree: Tree, fallback: Rgb) -> Rgb:
    """An SMC's colour in the graph: its salient object's, else its room's, else its branch's."""
    p = edge.smc.perception
    if p.cluster is not None:
        return cluster_rgb(p.cluster, tree)
    if p.room is not None:
        return hist_rgb(p.room, tree)
    return fallback


def hist_rgb(histogram: np.ndarray, tree: Tree) -> Rgb:
    """Dominant colour of a colour histogram (a room's, binned as the clusters')."""
    p = tree.params.perception
    return dominant_rgb(np.asarray(histogram), p.hue_bins, p.sat_bins, p.val_bins)


def sources_text(edge: Edge, limit: int = 3) -> str:
    """The logs and times an SMC was compiled from, the first ``limit`` of them."""
    parts = [f"{s.log} {s.t0:.1f}-{s.t1:.1f} s" for s in edge.sources[:limit]]
    if len(edge.sources) > limit:
        parts.append(f"+{len(edge.sources) - limit} more")
    return "; ".join(parts)


def perception_text(edge: Edge, tree: Tree) -> str:
    """Salient perceptions of an edge in a few words: object colour and size, weight."""
    parts = []
    c = edge.smc.perception.cluster
    if c is not None:
        ext = "x".join(f"{100 * e:.0f}" for e in c.extents)
        parts.append(f"{cluster_name(c, tree)} object {ext} cm")
    w = edge.smc.perception.weight
    if w is not None:
        parts.append(f"weight {1000 * w:.0f} g")
    p = edge.smc.perception
    if p.room is not None:
        parts.append(f"room mostly {colour_name(hist_rgb(p.room, tree))}")
    if p.scan is not None and p.scan_pose is not None:
        parts.append(f"scan at ({p.scan_pose[0]:.2f}, {p.scan_pose[1]:.2f})")
    elif p.room is not None:
        parts.append("no salient scan")
    return ", ".join(parts) or "no salient object"


def edge_label(edge: Edge, tree: Tree) -> str:
    """Graph label of an SMC: id, salient perceptions, gripper event, support, sources."""
    return (
        f"{edge.id}: {perception_text(edge, tree)}\n{edge.smc.action.event} · "
        f"support {edge.support}\n{sources_text(edge, 1)}"
    )


def branch_colours(tree: Tree) -> dict[str, Rgb]:
    """Edge id -> colour: a chain keeps its colour, each child of a fork starts a new one."""
    out: dict[str, Rgb] = {}
    k = 0
    stack: list[tuple[str, Rgb | None]] = [(ROOT, None)]
    while stack:
        node, colour = stack.pop()
        kids = tree.children(node)
        for e in reversed(kids):
            if colour is None or len(kids) > 1:
                c = PALETTE[k % len(PALETTE)]
                k += 1
            else:
                c = colour
            out[e.id] = c
            stack.append((e.child, c))
    for e in tree.edges:  # unreachable edges (should not exist): still coloured
        out.setdefault(e.id, PALETTE[7])
    return out
