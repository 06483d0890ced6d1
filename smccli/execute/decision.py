"""What one decision point of Algorithm 2 decided: the candidate SMCs with their D_P, the
chosen one, the mapped goal and the timings (the ``/smc/decision`` message)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True, slots=True)
class Candidate:
    """One child SMC considered at a decision point."""

    edge: str
    """Edge id."""
    node: str
    """Node it leaves."""
    d_p: float
    """D_P between the context and the SMC's salient perceptions (inf: not comparable)."""
    contingent: bool
    """C_Now: d_p < T_hP (eq. 36)."""
    cluster_index: int | None
    """Context cluster matched to the SMC's localized perception (eq. 39), if any; from
    :attr:`Decision.n_clusters` on, a union of two neighbouring clusters
    (:func:`~smccli.perception.cluster_unions`)."""
    terms: tuple[tuple[str, float], ...] = ()
    """A mobile base's D_P by sensor (``room``, ``scan``), and the ICP fitness of the scan's
    alignment (``icp_fitness``, not part of D_P)."""


@dataclass(frozen=True, slots=True)
class Decision:
    """One decision point of Algorithm 2."""

    t: float
    """Time of the decision [s] (:attr:`~smccli.execute.observation.Observation.t`: any clock)."""
    nodes: tuple[str, ...]
    """The frontier: the current node and the nodes equivalent to it."""
    candidates: tuple[Candidate, ...]
    """Every child of the frontier with its distances."""
    chosen: str | None
    """Edge taken (least contingent D_P, eq. 45), None when none was contingent."""
    mapped_goal: np.ndarray | None
    """Goal of the chosen action in the world [x, y, z, yaw] (eq. 38-39, 46)."""
    n_clusters: int
    """Object clusters seen."""
    weight: float | None
    """Scale reading [kg], None without a scale."""
    perceive_s: float
    """Wall time to perceive: extract the clusters (or the room's colours); the simulator
    loop adds the time to render and read its sensors [s]."""
    match_s: float
    """Wall time to match the candidates [s]."""
    duration: float = 0.0
    """Rollout duration of the chosen action [s]."""
    icp_s: float = 0.0
    """Wall time of the scan alignments, part of ``match_s`` [s]."""
    lidar_pose: np.ndarray | None = None
    """A mobile base's lidar pose in odometry's frame at the decision ``[x, y, yaw]``."""

    @property
    def latency_s(self) -> float:
        """Decision latency: perceive + match [s]."""
        return self.perceive_s + self.match_s

    def to_json(self) -> dict[str, Any]:
        """The ``/smc/decision`` message (schemas/smc_decision.schema.json)."""
        return {
            "node": self.nodes[0],
            "nodes": list(self.nodes),
            "candidates": [
                {
                    "edge": c.edge,
                    "node": c.node,
                    "d_p": _num(c.d_p),
                    "contingent": c.contingent,
                    "cluster": c.cluster_index,
                    **({"terms": {k: _num(v) for k, v in c.terms}} if c.terms else {}),
                }
                for c in self.candidates
            ],
            "chosen": self.chosen,
            "mapped_goal": None
            if self.mapped_goal is None
            else [float(v) for v in self.mapped_goal],
            "n_clusters": self.n_clusters,
            "weight": self.weight,
            "duration": self.duration,
            "timings": {
                "perceive": self.perceive_s,
                "match": self.match_s,
                "icp": self.icp_s,
                "total": self.latency_s,
            },
            **(
                {"lidar_pose": [float(v) for v in self.lidar_pose]}
                if self.lidar_pose is not None
                else {}
            ),
        }


def _num(x: float) -> float | None:
    return None if not math.isfinite(x) else float(x)
