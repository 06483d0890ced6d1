"""What goes into the recordings: one per log (the tree alone: one), their ids, the
blueprint and where its 3D view opens, and filling a stream with the tree and a log."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from smccli.inspect.labels import edge_label
from smccli.inspect.log_view import log_log
from smccli.inspect.mobile import is_mobile, mobile_view
from smccli.inspect.tree_view import log_tree
from smccli.inspect.views import (
    Framing,
    blueprint,
    floor_framing,
    graph_layout,
    workspace_framing,
)
from smccli.learn.tree import Tree

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb

    from smccli.logs.log import Log

APP_ID = "smc"
"""Rerun application id of every recording."""


def recording_plan(tree: Tree, logs: Sequence[Log], tree_name: str) -> list[tuple[str, Log | None]]:
    """(recording id, log or None) pairs: one per log, or one for the tree alone."""
    if not logs:
        return [(f"{Path(tree_name).stem}", None)]
    seen: dict[str, int] = {}
    plan: list[tuple[str, Log | None]] = []
    for log in logs:
        rid = Path(log.path).stem
        seen[rid] = seen.get(rid, 0) + 1
        plan.append((rid if seen[rid] == 1 else f"{rid}-{seen[rid]}", log))
    return plan


def blueprint_for(tree: Tree, logs: Sequence[Log]) -> rrb.Blueprint:
    """The blueprint with the graph fitted to this tree and the 3D view on its workspace."""
    labels = {e.id: edge_label(e, tree) for e in tree.edges}
    return blueprint(
        mobile=is_mobile(tree, logs),
        graph=graph_layout(tree, labels),
        framing=framing(tree, logs),
    )


def framing(tree: Tree, logs: Sequence[Log]) -> Framing:
    """Where the 3D view opens: an arm's perception crop (the workspace), a mobile base's
    rooms (from the first log's scene, else the tree's), else the paths the logs took."""
    if is_mobile(tree, logs):
        mobile = mobile_view(tree, logs[0] if logs else None)
        rects = [r for _, rs in (mobile.regions if mobile else ()) for r in rs]
        if rects:
            r = np.array(rects)
            return floor_framing(
                np.array([r[:, 0].min(), r[:, 2].min()]), np.array([r[:, 1].max(), r[:, 3].max()])
            )
        paths = [log.poi[:, :2] for log in logs if len(log.poi_t)]
        if paths:
            xy = np.concatenate(paths)
            return floor_framing(xy.min(axis=0) - 1.0, xy.max(axis=0) + 1.0)
        return floor_framing(np.array([-3.0, -3.0]), np.array([3.0, 3.0]))
    p = tree.params.perception
    return workspace_framing(np.array(p.crop_min), np.array(p.crop_max))


def fill(rec: rr.RecordingStream, tree: Tree, log: Log | None, warn: Callable[[str], None]) -> None:
    """Log the tree, and ``log`` if there is one, into ``rec``."""
    mobile = mobile_view(tree, log, warn)
    log_tree(rec, tree, mobile=mobile)
    if log is not None:
        log_log(rec, log, tree, warn=warn, mobile=mobile)
