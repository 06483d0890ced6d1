"""The tree in a recording (static):

- ``/tree``: the tree as a graph, one GraphNodes node per decision point and one
  GraphEdges edge per SMC; one labelled node per SMC at its edge (salient perceptions,
  gripper event, support, sources) and a swatch in its salient object's dominant colour
  (a mobile base's: its room's); ``/tree/smcs``: the same as a Markdown table.
- ``/world/actions/<edge>``: each SMC's DMP rolled out at its demonstrated start and goal
  (world frame), coloured by branch; ``.../goal`` its goal, ``.../object`` its salient
  object; a mobile base's stored scans, goal poses and rooms (:mod:`.mobile`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from smccli.inspect.labels import (
    SWATCH_GLYPH,
    TEXT_RGB,
    Rgb,
    branch_colours,
    cluster_name,
    cluster_rgb,
    edge_label,
    perception_text,
    sources_text,
    swatch_rgb,
)
from smccli.inspect.mobile import MobileView, goal_pose_world, log_rooms, log_stored_scan
from smccli.inspect.views import graph_layout
from smccli.learn.tree import ROOT, Edge, Tree
from smccli.world.geometry import xyzw, yaw_quat

if TYPE_CHECKING:
    import rerun as rr

    from smccli.perception.clusters import Cluster


def cluster_boxes(
    clusters: Sequence[Cluster], colours: Sequence[Rgb], labels: Sequence[str], radius: float
) -> rr.Boxes3D:
    """Object clusters as upright boxes (turned by their yaw), coloured and labelled."""
    import rerun as rr

    return rr.Boxes3D(
        centers=[c.centroid for c in clusters],
        half_sizes=[np.asarray(c.extents) / 2 for c in clusters],
        quaternions=[rr.Quaternion(xyzw=xyzw(yaw_quat(float(c.yaw)))) for c in clusters],
        colors=colours,
        labels=labels,
        radii=radius,
    )


def log_tree(rec: rr.RecordingStream, tree: Tree, *, mobile: MobileView | None = None) -> None:
    """The tree (static): graph at ``/tree``, actions under ``/world/actions``; for a mobile
    base (``mobile``, see :func:`mobile_view`) also the stored scans, goals and rooms."""
    import rerun as rr

    colours = branch_colours(tree)
    rec.log("/world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    _log_graph(rec, tree, colours)
    _log_table(rec, tree)
    for e in tree.edges:
        _log_action(rec, tree, e, colours[e.id], mobile)
    if mobile is not None:
        log_rooms(rec, mobile)


def _log_graph(rec: rr.RecordingStream, tree: Tree, colours: dict[str, Rgb]) -> None:
    """``/tree``: a node per decision point, per SMC a labelled node and a colour swatch
    (placed by :func:`graph_layout`), an edge per SMC."""
    import rerun as rr

    labels = {e.id: edge_label(e, tree) for e in tree.edges}
    layout = graph_layout(tree, labels)
    # Text takes its node's colour in Rerun's graph view: one neutral grey that reads on
    # the light and the dark theme; the object's colour goes to a swatch (a coloured
    # square, itself a labelled node) left of the label. One entity: the graph view draws
    # a titled frame around each entity's nodes.
    ids = [*tree.nodes]
    texts = [f"{n} (root)" if n == ROOT else n for n in tree.nodes]
    rgb = [TEXT_RGB] * len(tree.nodes)
    where = [layout.nodes[n] for n in tree.nodes]
    for e in tree.edges:
        ids += [e.id, f"{e.id} colour"]
        texts += [labels[e.id], SWATCH_GLYPH]
        rgb += [TEXT_RGB, swatch_rgb(e, tree, colours[e.id])]
        where += [layout.labels[e.id], layout.swatches[e.id]]
    rec.log("/tree", rr.GraphNodes(ids, positions=where, labels=texts, colors=rgb), static=True)
    rec.log(
        "/tree",
        rr.GraphEdges([(e.parent, e.child) for e in tree.edges], graph_type="directed"),
        static=True,
    )


def _goal_text(e: Edge) -> str:
    """An SMC's goal in its frame; a scan-frame goal also in the world."""
    g = e.smc.action.goal
    world = goal_pose_world(e)
    if e.smc.action.goal_frame == "scan" and world is not None:
        return (
            f"({g[0]:+.3f}, {g[1]:+.3f}, {math.degrees(g[3]):+.0f}°) scan → world "
            f"({world[0]:+.2f}, {world[1]:+.2f}, {math.degrees(world[2]):+.0f}°)"
        )
    return f"({g[0]:+.3f}, {g[1]:+.3f}, {g[2]:+.3f}) {e.smc.action.goal_frame}"


def _log_table(rec: rr.RecordingStream, tree: Tree) -> None:
    """``/tree/smcs``: the SMCs as a Markdown table under a heading."""
    import rerun as rr

    rows = [
        "| edge | parent → child | salient perceptions | event | goal | support | sources |",
        "|---|---|---|---|---|---|---|",
    ]
    for e in tree.edges:
        rows.append(
            f"| {e.id} | {e.parent} → {e.child} | {perception_text(e, tree)} | "
            f"{e.smc.action.event} | {_goal_text(e)} | {e.support} | {sources_text(e, 10)} |"
        )
    scene = tree.scene.get("name", "?")
    head = (
        f"# SMC tree, version {tree.version}\n\nscene {scene}, {len(tree.nodes)} nodes, "
        f"{len(tree.edges)} SMCs\n\n"
    )
    rec.log(
        "/tree/smcs",
        rr.TextDocument(head + "\n".join(rows), media_type="text/markdown"),
        static=True,
    )


def _log_action(
    rec: rr.RecordingStream, tree: Tree, e: Edge, colour: Rgb, mobile: MobileView | None
) -> None:
    """``/world/actions/<edge>``: the SMC's DMP rolled out at its demonstrated start and
    goal, its goal, its salient object; a mobile base's stored scan."""
    import rerun as rr

    from smccli.learn.dmp import rollout

    dmp = e.smc.action.dmp
    _, y = rollout(dmp, start=dmp.start, goal=dmp.goal)
    base = f"/world/actions/{e.id}"
    rec.log(
        base,
        rr.LineStrips3D(
            [y[:, :3]],
            colors=[colour],
            radii=0.005 if mobile is None else 0.02,
            labels=[e.id],
        ),
        static=True,
    )
    if mobile is not None:
        log_stored_scan(rec, e, colour, mobile)
    rec.log(
        f"{base}/goal",
        rr.Points3D([dmp.goal[:3]], colors=[colour], radii=0.008),
        static=True,
    )
    c = e.smc.perception.cluster
    if c is not None:
        rec.log(
            f"{base}/object",
            cluster_boxes([c], [cluster_rgb(c, tree)], [f"{e.id}: {cluster_name(c, tree)}"], 0.001),
            static=True,
        )
