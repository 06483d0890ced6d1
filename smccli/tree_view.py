"""Text rendering of an SMC tree for the terminal (``smc compile`` prints it)."""

from __future__ import annotations

from rich.console import Console
from rich.markup import escape
from rich.tree import Tree as RichTree

from smccli.colours import colour_name, dominant_rgb
from smccli.perception import Cluster, PerceptionParams
from smccli.smc import Smc
from smccli.tree import ROOT, Tree


def _colour(cluster: Cluster, p: PerceptionParams) -> str:
    return colour_name(dominant_rgb(cluster.histogram, p.hue_bins, p.sat_bins, p.val_bins))


def describe_perception(smc: Smc, params: PerceptionParams | None = None) -> str:
    """One-line summary of an SMC's salient perceptions."""
    parts = []
    c = smc.perception.cluster
    if c is not None:
        ext = "x".join(f"{100 * e:.0f}" for e in c.extents)
        parts.append(
            f"{_colour(c, params or PerceptionParams())} object {ext} cm at "
            f"({c.centroid[0]:.2f}, {c.centroid[1]:.2f})"
        )
    if smc.perception.weight is not None:
        parts.append(f"weight {1000 * smc.perception.weight:.0f} g")
    return ", ".join(parts) or "nothing localized"


def describe_action(smc: Smc) -> str:
    """One-line summary of an SMC's action."""
    a = smc.action
    g = a.goal
    where = "rel. object" if a.goal_frame == "object" else "world"
    return (
        f"{a.event} | goal ({g[0]:+.3f}, {g[1]:+.3f}, {g[2]:+.3f}) m {where}, "
        f"{a.dmp.duration:.1f} s"
    )


def print_tree(tree: Tree, console: Console) -> None:
    """Print nodes and edges as an indented tree."""
    root = RichTree(f"[bold]{ROOT}[/] (root)")
    stack = [(ROOT, root)]
    while stack:
        node, branch = stack.pop()
        added = []
        for e in tree.children(node):
            srcs = escape(", ".join(f"{s.log}@{s.t0:.1f}-{s.t1:.1f}s" for s in e.sources))
            what = describe_perception(e.smc, tree.params.perception)
            child = branch.add(
                f"[cyan]{e.id}[/] -> [bold]{e.child}[/]  {what}  ||  "
                f"{describe_action(e.smc)}  [dim]support {e.support}: {srcs}[/]"
            )
            added.append((e.child, child))
        stack.extend(reversed(added))
    console.print(root)
