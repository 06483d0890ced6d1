"""What to do after a decision point (:class:`Plan`): the chosen action mapped to the context
and its DMP rolled out at the robot's control period (eq. 38-39, 46)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from smccli.execute.decision import Decision
from smccli.learn.dmp import rollout
from smccli.learn.smc import Action
from smccli.perception import Cluster

DURATION_CLIP = (0.5, 2.5)
"""Bounds of the duration scale (new start-goal distance over the demonstrated one)."""
MAX_YAW_RATE = 1.5
"""A rollout lasts at least |yaw change| / this [s] (the wrist's comfortable speed) [rad/s]."""
MIN_DURATION = 0.5
"""Shortest rollout [s]."""
MIDWAY_PHASE = 0.95
"""A gripper switch before this phase of a fragment happens midway through the rollout."""

STOPS = ("no_contingent_smc", "target_unreachable")
"""Why a plan may stop the task (:attr:`Plan.stop`)."""


@dataclass(frozen=True, eq=False)
class Plan:
    """What to do after a decision point: the chosen action, mapped and rolled out.

    Execute it so (as :class:`~smccli.execute.executor.TreeExecutor` does): stream
    ``poses[1:]``, one per control period, with the gripper commanded to
    ``gripper_start``; at ``switch_index`` (when the switch is midway, ``switch_index <
    len(poses) - 1``) hold that pose until the POI is there, command ``gripper_end``, wait
    for the fingers to stop, and stream the rest with ``gripper_end``; hold ``goal`` until
    the POI is there; a switch at the end (``switch_index == len(poses) - 1``) comes now.
    Then :meth:`~smccli.execute.policy.TreePolicy.advance`.
    """

    decision: Decision | None
    """The decision point (candidates with D_P, chosen edge, mapped goal, timings); None
    only when ``done`` (a leaf has no decision to make)."""
    edge: str | None = None
    """Id of the chosen edge (None when done or no SMC was contingent)."""
    goal: np.ndarray | None = None
    """The action's goal mapped to the context, ``[x, y, z, yaw]`` in the observation's
    frame (eq. 38-39, 46), the yaw unwrapped next to the start's."""
    times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(n,) time of each pose from the start of the action [s]: 0, one control period,
    ..., ``duration``. Empty when there is nothing to execute."""
    poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    """(n, 4) the rolled-out DMP ``[x, y, z, yaw]``: POI targets, ``poses[0]`` the start
    (the observation's POI), ``poses[-1]`` the goal."""
    gripper_start: float | None = None
    """Gripper command (1 open, 0 closed) from the start, None when nothing to execute."""
    gripper_end: float | None = None
    """Gripper command after the switch (same as ``gripper_start`` without one)."""
    switch_index: int | None = None
    """Index into ``poses`` where the gripper switches to ``gripper_end``; None: no switch."""
    gripper_switch: float | None = None
    """When the gripper switches, ``times[switch_index]`` [s from the start]; None: no switch."""
    event: str = "none"
    """The gripper event: ``close``, ``open`` or ``none``."""
    duration: float = 0.0
    """Duration of the rollout [s] (the demonstrated one scaled by the distance)."""
    done: bool = False
    """A leaf is reached: the task is over, there is nothing to execute."""
    stopped: bool = False
    """No action can be taken here (``stop`` says why, ``reason`` in one line)."""
    stop: str | None = None
    """``no_contingent_smc`` (no child SMC's perceptions match the context) or
    ``target_unreachable`` (the mapped goal is out of the arm's reach; checked only with
    a model), None otherwise (:data:`STOPS`)."""
    reason: str = ""
    """Why done or stopped, one line (the distances of every candidate at a stop)."""
    scan_alignment: np.ndarray | None = None
    """A mobile base's scan-frame goal: the current lidar in the taught lidar's frame, the
    SE(2) transform (3, 3) that mapped the goal (for correcting the goal while driving)."""
    poi: str | None = None
    """A mobile manipulator's: what ``poses`` drive, ``"hand"`` (the hand in odometry's
    frame; send each in the frame of the base's target of the same tick) or ``"base"``
    (the base ``[x, y, 0, yaw]``; the hand rides along). None: the robot's one POI."""
    base_poses: np.ndarray | None = None
    """A mobile manipulator's hand plan that also drives the base: (n, 4) base targets
    ``[x, y, 0, yaw]`` on the same clock as ``poses`` (two DMPs, one duration)."""
    cluster: Cluster | None = None
    """The object an arm's goal was mapped on (a goal in its frame), where the decision saw
    it: the executor looks for it again while the action runs
    (:meth:`~smccli.execute.policy.TreePolicy.look_again`)."""
    grasp_shift: float = 0.0
    """How far the grasp was moved along the goal's x from the demonstrated one, where its
    fingers had room (:mod:`smccli.execute.grasp`) [m]; a goal mapped again keeps it."""

    @property
    def midway(self) -> bool:
        """The gripper switches before the goal (hold ``poses[switch_index]`` there)."""
        return self.switch_index is not None and self.switch_index < len(self.poses) - 1


def action_duration(action: Action, start: np.ndarray, goal: np.ndarray) -> float:
    """The demonstrated duration scaled by the start-goal distance, so speeds stay human [s]."""
    dmp = action.dmp
    demo = float(np.linalg.norm(dmp.goal[:3] - dmp.start[:3]))
    new = float(np.linalg.norm(goal[:3] - start[:3]))
    scale = float(np.clip(new / max(demo, 1e-3), *DURATION_CLIP))
    return max(MIN_DURATION, dmp.duration * scale, abs(goal[3] - start[3]) / MAX_YAW_RATE)


def rollout_steps(duration: float, control_period: float) -> int:
    """Poses in a rollout of ``duration`` [s] at ``control_period`` [s]: one per period and
    the start, at least 3."""
    return max(2, round(duration / control_period)) + 1


def switch_index(action: Action, n: int) -> int | None:
    """Index of the gripper's switch in a rollout of ``action`` of ``n`` poses: at its
    phase when that comes before :data:`MIDWAY_PHASE` (e.g. grasp, then lift; never at
    the last pose, which means at the goal), else at the goal; None without an event."""
    if action.event == "none":
        return None
    if action.gripper_phase < MIDWAY_PHASE:
        return min(int(round(action.gripper_phase * (n - 1))), n - 2)
    return n - 1


def switch_pose(
    action: Action, start: np.ndarray, goal: np.ndarray, control_period: float
) -> np.ndarray:
    """Where the POI is ``[x, y, z, yaw]`` when the gripper switches in the rollout of
    ``action`` from ``start`` to ``goal`` (:func:`rolled_out`'s): the goal itself unless
    the switch comes midway."""
    if action.event == "none" or action.gripper_phase >= MIDWAY_PHASE:
        return np.asarray(goal, dtype=float)
    duration = action_duration(action, start, goal)
    n_steps = rollout_steps(duration, control_period)
    _, poses = rollout(action.dmp, start=start, goal=goal, duration=duration, n_steps=n_steps)
    i = switch_index(action, len(poses))
    assert i is not None
    return poses[i]


def rolled_out(
    decision: Decision,
    edge: str,
    action: Action,
    start: np.ndarray,
    goal: np.ndarray,
    control_period: float,
    base: tuple[np.ndarray, np.ndarray] | None = None,
    scan_alignment: np.ndarray | None = None,
    cluster: Cluster | None = None,
    opening: float | None = None,
    grasp_shift: float = 0.0,
) -> Plan:
    """The plan that runs ``action`` of ``edge`` from ``start`` to the mapped ``goal``
    ``[x, y, z, yaw]``: its DMP rolled out over :func:`action_duration` at
    ``control_period`` [s], the gripper's switch placed at its phase. ``base``: a mobile
    manipulator's base (now, goal) ``[x, y, 0, yaw]`` when the action drives it too;
    ``scan_alignment``, ``cluster`` and ``grasp_shift`` as :class:`Plan` holds them;
    ``opening``: the fingers' opening on the way [0-1] instead of the demonstrated one."""
    duration = action_duration(action, start, goal)
    n_steps = rollout_steps(duration, control_period)
    times, poses = rollout(action.dmp, start=start, goal=goal, duration=duration, n_steps=n_steps)
    base_poses = None
    if base is not None and action.base_dmp is not None:
        _, base_poses = rollout(
            action.base_dmp, start=base[0], goal=base[1], duration=duration, n_steps=n_steps
        )
    # Closed means squeeze; open as demonstrated (fingers opened only part way past a
    # door's edge onto its handle), or as the fingers' room allows.
    start_grip = float(action.gripper_start) if action.gripper_start >= 0.5 else 0.0
    switch = switch_index(action, len(poses))
    return Plan(
        decision=decision,
        edge=edge,
        goal=goal,
        times=times,
        poses=poses,
        gripper_start=opening if opening is not None else start_grip,
        gripper_end=float(action.gripper_end) if action.gripper_end >= 0.5 else 0.0,
        switch_index=switch,
        gripper_switch=None if switch is None else float(times[switch]),
        event=action.event,
        duration=duration,
        scan_alignment=scan_alignment,
        poi=action.poi,
        base_poses=base_poses,
        cluster=cluster,
        grasp_shift=grasp_shift,
    )
