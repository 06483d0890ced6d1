"""Where inspect's views look: the blueprint, the tree graph's layout, the 3D framing.

The graph runs top down (a row per depth, a column per leaf as wide as the widest label),
each SMC's label on its edge just above the node it leads to, so two labels are a row or
a column apart and never overlap; the graph view opens on bounds that hold every node and
label. The 3D view
opens on the workspace (the perception crop of an arm, the rooms of a mobile base), and
leaves the depth image out of it (back-projected through the pinhole, the floor and walls
behind the table would fill the view; it keeps its own 2D panel, and the decision points'
cropped clouds stay in 3D).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from smccli.learn.tree import ROOT, Tree

if TYPE_CHECKING:
    import rerun.blueprint as rrb

CHAR_W = 7.0
"""Width of one label character in graph-view units (Rerun's label font at zoom 1)."""
LINE_H = 17.0
"""Height of one label line in graph-view units."""
NODE_W = 80.0
"""Width of a decision point's label box (``n12 (root)``) [graph units]."""
NODE_H = 24.0
"""Height of a decision point's label box [graph units]."""
GAP = 24.0
"""Space between a node, an edge label and the next node or label [graph units]."""
SWATCH = 12.0
"""Distance from a label box's left side to its colour swatch [graph units]."""


@dataclass(frozen=True, slots=True)
class GraphLayout:
    """Positions in the graph view [graph units, y down]."""

    nodes: dict[str, tuple[float, float]]
    """Decision point -> centre of its label box."""
    labels: dict[str, tuple[float, float]]
    """Edge id -> centre of its label box (just left of the child node)."""
    swatches: dict[str, tuple[float, float]]
    """Edge id -> its colour swatch, left of the label."""
    bounds: tuple[tuple[float, float], tuple[float, float]]
    """(x_min, x_max), (y_min, y_max) holding every box: the view's initial bounds."""


def text_size(text: str) -> tuple[float, float]:
    """(width, height) of a label box for ``text`` [graph units] (an estimate)."""
    lines = text.splitlines() or [""]
    return CHAR_W * max(len(line) for line in lines) + 12.0, LINE_H * len(lines) + 8.0


def graph_layout(tree: Tree, labels: dict[str, str]) -> GraphLayout:
    """Lay the tree out top down; ``labels`` maps edge id -> its label text.

    Leaves take one column each, as wide as the widest label; a node sits above the middle
    of its children; each label sits on its edge just above the child, so two labels are
    a column or a row apart.
    """
    depth = {ROOT: 0}
    order = [ROOT]
    for node in order:  # breadth first from the root
        for e in tree.children(node):
            if e.child not in depth:
                depth[e.child] = depth[node] + 1
                order.append(e.child)
    size = {e.id: text_size(labels.get(e.id, e.id)) for e in tree.edges}
    widest = max((w for w, _ in size.values()), default=NODE_W)
    tallest = max((h for _, h in size.values()), default=LINE_H)
    column = max(widest + SWATCH + 16.0, NODE_W) + GAP
    row = NODE_H + tallest + 2 * GAP + 8.0
    xs: dict[str, float] = {}
    next_col = [0.0]

    def place(node: str) -> float:
        kids = [e.child for e in tree.children(node) if depth.get(e.child) == depth[node] + 1]
        if not kids:
            x = next_col[0]
            next_col[0] += column
        else:
            placed = [place(k) for k in kids]
            x = (min(placed) + max(placed)) / 2
        xs[node] = x
        return x

    place(ROOT)
    for n in tree.nodes:  # nodes not under the root (should not exist): a column each
        if n not in xs:
            depth[n] = 0
            xs[n] = next_col[0]
            next_col[0] += column
    nodes = {n: (xs[n], row * depth[n]) for n in tree.nodes}
    label_pos: dict[str, tuple[float, float]] = {}
    swatch_pos: dict[str, tuple[float, float]] = {}
    for e in tree.edges:
        cx, cy = nodes[e.child]
        w, h = size[e.id]
        y = cy - NODE_H / 2 - GAP - h / 2
        label_pos[e.id] = (cx, y)
        swatch_pos[e.id] = (cx - w / 2 - SWATCH, y)
    x_lo = min(
        [x - NODE_W / 2 for x, _ in nodes.values()] + [x - 8 for x, _ in swatch_pos.values()]
    )
    x_hi = max(
        [x + NODE_W / 2 for x, _ in nodes.values()]
        + [label_pos[e.id][0] + size[e.id][0] / 2 for e in tree.edges]
    )
    y_lo = min(y for _, y in nodes.values()) - NODE_H
    y_hi = max(y for _, y in nodes.values()) + NODE_H
    pad = 20.0
    return GraphLayout(
        nodes, label_pos, swatch_pos, ((x_lo - pad, x_hi + pad), (y_lo - pad, y_hi + pad))
    )


@dataclass(frozen=True, slots=True)
class Framing:
    """The 3D view's initial eye [m, world frame]."""

    target: tuple[float, float, float]
    """Where the eye looks and orbits around."""
    eye: tuple[float, float, float]
    """Where the eye is."""


def workspace_framing(lo: np.ndarray, hi: np.ndarray) -> Framing:
    """An eye on the box ``lo``-``hi`` [m]: from beside and above the robot at the origin,
    far enough for the box to fill most of the view."""
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    centre = (lo + hi) / 2
    target = np.array([centre[0], centre[1], lo[2] + 0.2])
    span = float(np.linalg.norm((hi - lo)[:2]))
    # Behind the robot's base and to its right, looking down at about 35 degrees.
    direction = np.array([-0.75, -0.55, 0.65])
    eye = target + 1.0 * span * direction / np.linalg.norm(direction)
    return Framing(tuple(map(float, target)), tuple(map(float, eye)))  # type: ignore[arg-type]


def floor_framing(lo: np.ndarray, hi: np.ndarray) -> Framing:
    """An eye on a floor plan ``lo``-``hi`` (x, y) [m]: above, from the south, steeply."""
    lo, hi = np.asarray(lo, dtype=float)[:2], np.asarray(hi, dtype=float)[:2]
    centre = (lo + hi) / 2
    span = float(np.max(hi - lo))
    target = np.array([centre[0], centre[1], 0.0])
    eye = target + span * np.array([0.0, -0.55, 0.95])
    return Framing(tuple(map(float, target)), tuple(map(float, eye)))  # type: ignore[arg-type]


TIMELINE = "time"


def blueprint(
    *, mobile: bool = False, graph: GraphLayout | None = None, framing: Framing | None = None
) -> rrb.Blueprint:
    """Graph and time series on the left, 3D world, camera, depth and events on the right;
    ``mobile``: a tab with the room histograms next to the events. ``graph`` and
    ``framing`` set where the graph and the 3D views open."""
    import rerun.blueprint as rrb

    tabs = [
        rrb.TextLogView(origin="/events", name="events"),
        rrb.TextDocumentView(origin="/tree/smcs", name="SMCs"),
    ]
    if mobile:
        tabs.append(rrb.BarChartView(origin="/signals/room_histogram", name="room histogram"))
    graph_kw: dict[str, Any] = {}
    if graph is not None:
        (x0, x1), (y0, y1) = graph.bounds
        graph_kw["visual_bounds"] = rrb.VisualBounds2D(x_range=[x0, x1], y_range=[y0, y1])
    world_kw: dict[str, Any] = {}
    if framing is not None:
        world_kw["eye_controls"] = rrb.EyeControls3D(
            position=framing.eye, look_target=framing.target, eye_up=(0.0, 0.0, 1.0)
        )
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.GraphView(origin="/tree", name="SMC tree", **graph_kw),
                rrb.TimeSeriesView(origin="/signals", name="signals"),
                row_shares=[3, 2],
            ),
            rrb.Vertical(
                rrb.Spatial3DView(
                    origin="/world",
                    contents=["+ $origin/**", "- /world/camera/depth"],
                    name="world",
                    **world_kw,
                ),
                rrb.Horizontal(
                    rrb.Spatial2DView(
                        origin="/world/camera", contents="$origin/image", name="camera"
                    ),
                    rrb.Spatial2DView(
                        origin="/world/camera", contents="$origin/depth", name="depth"
                    ),
                    rrb.Tabs(*tabs),
                ),
                row_shares=[3, 2],
            ),
            column_shares=[1, 1],
        ),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE, state="expanded"),
    )
