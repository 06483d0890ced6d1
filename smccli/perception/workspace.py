"""Warnings for objects the workspace crop box may cut (record, doctor, compile).

The box itself, where a scene sets none, is :func:`~smccli.perception.reach.workspace_box`.
"""

from __future__ import annotations

from collections.abc import Sequence

from smccli.perception.clusters import Cluster
from smccli.perception.params import PerceptionParams


def crop_warnings(
    where: str, t: float, clusters: Sequence[Cluster], params: PerceptionParams, seen: set[str]
) -> list[str]:
    """One line per crop-box face that a cluster of a decision frame at ``t`` [s] reaches
    and ``seen`` does not yet hold (added to it): the box may cut that object, and which
    setting moves the face."""
    lines = []
    for c in clusters:
        for face in c.crop_faces:
            if face in seen:
                continue
            seen.add(face)
            axis, side = face.split("_")
            k = "xyz".index(axis)
            corner = params.crop_min if side == "min" else params.crop_max
            lines.append(
                f"{where}: at t={t:.1f} s an object at ({c.centroid[0]:.3f}, "
                f"{c.centroid[1]:.3f}) m reaches the crop box's {face} face ({axis} = "
                f"{corner[k]:.3f} m{', base frame' if params.crop_frame == 'base' else ''}): "
                f"part of it may be cut off; move perception.crop_{side} in the scene file"
            )
    return lines
