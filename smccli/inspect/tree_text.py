"""One line of text per SMC of a tree, for people (``smc compile`` prints the tree with them)."""

from __future__ import annotations

from smccli.learn.smc import Smc
from smccli.perception import Cluster, PerceptionParams
from smccli.perception.colours import colour_name, dominant_rgb


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
    p = params or PerceptionParams()
    if smc.perception.room is not None:
        rgb = dominant_rgb(smc.perception.room, p.hue_bins, p.sat_bins, p.val_bins)
        parts.append(f"room mostly {colour_name(rgb)}")
    if smc.perception.scan is not None and smc.perception.scan_pose is not None:
        x, y, _ = smc.perception.scan_pose
        parts.append(
            f"scan of {int(smc.perception.scan.valid().sum())} returns at ({x:.2f}, {y:.2f})"
        )
    return ", ".join(parts) or "nothing localized"


def describe_action(smc: Smc) -> str:
    """One-line summary of an SMC's action."""
    a = smc.action
    g = a.goal
    where = {
        "object": "rel. object",
        "scan": "rel. scan",
        "base": "rel. base",
        "hand": "rel. hand",
    }.get(a.goal_frame, "world")
    return (
        f"{a.event} | goal ({g[0]:+.3f}, {g[1]:+.3f}, {g[2]:+.3f}) m {where}, "
        f"{a.dmp.duration:.1f} s"
    )
