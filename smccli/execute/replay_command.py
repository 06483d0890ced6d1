"""``smc replay``'s options checked before anything runs: which run they ask for (a
recorded log's commands played again, a campaign, or one episode), and the odometry drift
they give."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from smccli.errors import SmcError
from smccli.world.sim import OdometryDrift

ReplayKind = Literal["verify", "campaign", "episode"]
"""``verify``: a log's commands again (``--verify LOG``); ``campaign``: ``--trials N``
randomised layouts; ``episode``: one run of the tree."""


def replay_kind(
    *,
    tree: Path | None,
    trials: int,
    workers: int,
    cluster: str | None,
    teach: str | None,
    script: Path | None,
    verify: Path | None,
) -> ReplayKind:
    """The run ``smc replay``'s options ask for; SmcError (one line naming the options)
    for a combination that means nothing. ``workers`` 0: the default (all cores)."""
    if verify is not None:
        if tree is not None or trials > 0:
            raise SmcError("--verify LOG replays a recording's commands: give no tree or --trials")
        return "verify"
    if tree is None:
        raise SmcError("replay needs a tree file (or --verify LOG)")
    if teach is not None and trials > 0:
        raise SmcError("--teach continues one episode; it does not go with --trials")
    if script is not None and teach is None:
        raise SmcError("--script is the continuation of --teach script")
    if cluster is not None and trials <= 0:
        raise SmcError("--cluster runs a campaign's trials: give --trials N")
    if cluster is not None and workers:
        raise SmcError("--workers counts local processes; with --cluster the cluster's run")
    return "campaign" if trials > 0 else "episode"


def odometry_drift(fraction: float) -> OdometryDrift | None:
    """``--odometry-drift``: distance off by ``fraction`` and heading off by ``fraction``
    rad per metre driven; None for 0 (exact odometry)."""
    return OdometryDrift(fraction, fraction) if fraction > 0 else None
