"""Executing an SMC tree in simulation (paper 3.6, 3.9, Algorithm 2, 5.1).

Modules: :mod:`~smccli.execute.sensing` (what control may use),
:mod:`~smccli.execute.executor` (Algorithm 2), :mod:`~smccli.execute.evaluation` (scoring
after control, from the simulator's truth), :mod:`~smccli.execute.replay_log` (the replay
MCAP log), :mod:`~smccli.execute.episode` (one episode) and
:mod:`~smccli.execute.campaign` (many, with statistics).
"""

from smccli.execute.campaign import run_campaign
from smccli.execute.episode import resolve, run_episode

__all__ = ["resolve", "run_campaign", "run_episode"]
