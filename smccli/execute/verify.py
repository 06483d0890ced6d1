"""``smc replay --verify LOG``: does a log mean what it recorded?

The demonstration's commands are played again, tick by tick, on the scene the log
carries (its attachments), from the log's initial state (objects and furniture from the
first ground-truth message, a mobile base from its first pose), and the robot's state
after each command is compared with the state the log recorded after it: the POI
(position and yaw), the fingers and the other joints. MuJoCo is deterministic, so a log
written by this simulator at this commit replays to the bit; a log whose commands were
edited, or that comes from another model or controller, drifts. The verdict: divergent
when the POI is ever more than :data:`POI_TOLERANCE` away or a finger more than
:data:`FINGER_TOLERANCE`: what the robot learns from and does. The other joints are
reported, not judged: a 7-joint arm's posture may drift along its free (null-space)
direction with the hand where it was.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from smccli.errors import LogError
from smccli.logs import read_log
from smccli.logs import topics as tp
from smccli.world.geometry import quat_yaw, wrap
from smccli.world.scene import ROBOT_KEY, Layout, scene_of_log
from smccli.world.sim import Sim

POI_TOLERANCE = 0.005
"""Largest POI difference [m] (yaw counts as 0.1 m per rad) a log may show and still mean
what it recorded. Above a finger's width of what a grasp tolerates, well above the
floating-point noise of another CPU."""
FINGER_TOLERANCE = 0.002
"""Largest finger joint difference [m or rad] of a log that means what it recorded."""
YAW_WEIGHT = 0.1
"""Metres per radian of POI yaw in the POI difference (a 10 cm lever)."""


@dataclass(frozen=True, slots=True)
class Verification:
    """How far a log's re-simulation strays from what it recorded."""

    log: Path
    scene: str
    t: np.ndarray
    """Times of the compared states, shape (n,) [s]."""
    poi_error: np.ndarray
    """POI difference after each command, shape (n,) [m] (yaw weighted by YAW_WEIGHT)."""
    finger_error: np.ndarray
    """Largest finger joint difference after each command, shape (n,) [m or rad]."""
    joint_error: np.ndarray
    """Largest difference of the other joints (base, arm) after each command, shape (n,)
    [rad or m]; reported, not judged."""

    @property
    def max_poi_error(self) -> float:
        return float(self.poi_error.max(initial=0.0))

    @property
    def max_finger_error(self) -> float:
        return float(self.finger_error.max(initial=0.0))

    @property
    def max_joint_error(self) -> float:
        return float(self.joint_error.max(initial=0.0))

    @property
    def divergent(self) -> bool:
        return self.max_poi_error > POI_TOLERANCE or self.max_finger_error > FINGER_TOLERANCE

    @property
    def first_divergence(self) -> float | None:
        """Time [s] the state first strayed beyond a tolerance, None if it never did."""
        bad = (self.poi_error > POI_TOLERANCE) | (self.finger_error > FINGER_TOLERANCE)
        return float(self.t[np.argmax(bad)]) if bad.any() else None


def initial_layout(
    ground_truth: list[tuple[float, dict[str, np.ndarray]]],
    base: np.ndarray | None,
    parked_z: float,
) -> Layout:
    """The layout a log started from: the first ground truth's object poses ``[x, y, z,
    qw, qx, qy, qz]`` as ``[x, y, z, yaw]``, leaving out objects parked at or below
    ``parked_z`` [m] (:attr:`Sim.park_z`: another variant's), a mobile base's first pose
    ``[x, y, yaw]`` as :data:`ROBOT_KEY`."""
    _, poses = ground_truth[0]
    layout: Layout = {}
    for name, p in poses.items():
        if p[2] <= parked_z + 1e-6:
            continue
        yaw = quat_yaw(p[3:7])
        layout[name] = (float(p[0]), float(p[1]), float(p[2]), yaw)
    if base is not None:
        layout[ROBOT_KEY] = (float(base[0]), float(base[1]), 0.0, float(base[2]))
    return layout


def verify_log(path: str | Path) -> Verification:
    """Re-simulate ``path``'s commands from its initial state; see the module docstring.

    LogError (one line naming the file) for a log without commands, states or ground truth.
    """
    path = Path(path)
    need = (tp.COMMAND, tp.JOINT_STATES, tp.POI, tp.GROUND_TRUTH)
    log = read_log(path, topics=(*need, tp.BASE), required_topics=need)
    scene = scene_of_log(log.attachments, path)
    mobile = scene.robot.base is not None
    base0 = None
    if mobile:
        base0 = log.base[0] if len(log.base) else log.poi[0][[0, 1, 3]]
    states = len(log.joint_states)
    if states != len(log.commands) + 1 or len(log.poi) != states:
        raise LogError(
            f"{path}: {len(log.commands)} commands but {states} joint states and "
            f"{len(log.poi)} POIs; a recording has one state before the first command and "
            "one after each"
        )
    sim = Sim(scene)
    try:
        sim.reset(initial_layout(log.ground_truth, base0, sim.park_z))
        names = sim.joint_state().names
        logged_names = log.joint_states[0].names
        if tuple(names) != tuple(logged_names):
            raise LogError(
                f"{path}: joints {', '.join(logged_names)} are not its scene's robot's "
                f"({', '.join(names)})"
            )
        fingers = np.isin(names, scene.robot.gripper.joints if scene.robot.gripper else ())
        n = len(log.commands)
        poi_err, finger_err, joint_err = np.zeros(n), np.zeros(n), np.zeros(n)
        for k, cmd in enumerate(log.commands):
            sim.step(cmd)
            want, got = log.poi[k + 1], sim.poi()
            dyaw = wrap(float(got[3] - want[3]))
            poi_err[k] = math.hypot(float(np.linalg.norm(got[:3] - want[:3])), YAW_WEIGHT * dyaw)
            dq = np.abs(sim.joint_state().position - log.joint_states[k + 1].position)
            finger_err[k] = float(dq[fingers].max(initial=0.0))
            joint_err[k] = float(dq[~fingers].max(initial=0.0))
    finally:
        sim.close()
    return Verification(
        log=path,
        scene=scene.name,
        t=log.poi_t[1:].copy(),
        poi_error=poi_err,
        finger_error=finger_err,
        joint_error=joint_err,
    )
