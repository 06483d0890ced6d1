"""Executing an SMC tree (paper 3.6, 3.9, Algorithm 2, 5.1).

Modules: :mod:`~smccli.execute.policy` (Algorithm 2 one decision at a time, for any runtime:
a robot's control loop or the simulator's), :mod:`~smccli.execute.sensing` (what control may
use in simulation), :mod:`~smccli.execute.executor` (the simulator's loop around the policy),
:mod:`~smccli.execute.evaluation` (scoring after control, from the simulator's truth),
:mod:`~smccli.execute.replay_log` (the replay MCAP log), :mod:`~smccli.execute.episode` (one
episode) and :mod:`~smccli.execute.campaign` (many, with statistics).
"""

from smccli.execute.campaign import run_campaign
from smccli.execute.episode import resolve, run_episode
from smccli.execute.policy import Candidate, Decision, Observation, Plan, TreePolicy

__all__ = [
    "Candidate",
    "Decision",
    "Observation",
    "Plan",
    "TreePolicy",
    "resolve",
    "run_campaign",
    "run_episode",
]
