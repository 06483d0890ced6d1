"""One demonstration -> its SMC chain (paper 3.1-3.7, eq. 40-42).

In order: temporal saliency (the log's fragments) -> perception saliency -> action
saliency -> one SMC per fragment, for an arm here, for a mobile base or a mobile
manipulator in :mod:`smccli.learn.mobile`. Only the logged sensors are perceived through
(camera, scale, the robot's own joints for the self-filter); ``/sim/ground_truth`` is never
read.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from smccli.errors import LogError, SmcError
from smccli.learn.mobile import base_smcs, mobile_manipulator_smcs
from smccli.learn.params import SmcParams, with_overrides
from smccli.learn.segmentation import (
    Fragment,
    SegmentMode,
    fragment_commands,
    segment,
    trace_from_commands,
)
from smccli.learn.smc import Action, SalientPerceptions, Smc, action_from_path
from smccli.learn.trim import active_times, idle_centres
from smccli.logs import Log, read_log
from smccli.logs import topics as tp
from smccli.logs.robot import geometry_at, robot_model_of
from smccli.perception import Cluster, clusters_from_frame, salient_cluster, scale_reading
from smccli.perception.params import scene_perception
from smccli.perception.workspace import crop_warnings
from smccli.world.robot import Robot
from smccli.world.scene import Scene, scene_of_log


@dataclass(frozen=True, slots=True)
class Chain:
    """The SMCs extracted from one log, in time order."""

    log: Path
    """The log file."""
    sha256: str
    """Its sha256 (hex)."""
    fragments: tuple[Fragment, ...]
    """Temporal saliency: the fragments."""
    smcs: tuple[Smc, ...]
    """One SMC per fragment."""
    warnings: tuple[str, ...]
    """One-line warnings (truncated log, no boundary, no salient object...)."""
    at: str | None = None
    """Where the chain was taught during replay (``smc replay --teach``) and inserted; None:
    a demonstration of the whole task, inserted at the root."""


def _finger_speed(log: Log, fingers: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Largest speed of the gripper joints ``fingers`` over time, for settling the gripper
    edges."""
    t = np.array([js.t for js in log.joint_states], dtype=float)
    if not log.joint_states:
        return t, np.zeros(0)
    names = log.joint_states[0].names
    idx = [i for i, n in enumerate(names) if n in fingers]
    if not idx:
        return t, np.zeros(len(t))
    vel = np.abs(np.array([js.velocity for js in log.joint_states])[:, idx]).max(axis=1)
    return t, vel


def fragments(
    log: Log,
    params: SmcParams,
    mode: SegmentMode = SegmentMode.markers,
    robot: Robot | None = None,
) -> list[Fragment]:
    """Temporal saliency (3.1) of a log: its fragments, as compile cuts them. ``robot``:
    the log's (default: read from its attachments)."""
    robot = robot or scene_of_log(log.attachments, log.path).robot
    t_end = float(log.poi_t[-1]) if len(log.poi_t) else 0.0
    t_f, v_f = _finger_speed(log, robot.gripper.joints if robot.gripper else ())
    marks = tuple(m.t for m in log.marks if m.source == "operator")
    trace = trace_from_commands(log.commands, t_f, v_f, log.weight_t, log.weight, marks, t_end)
    return segment(
        trace,
        mode,
        snap_window=params.snap_window,
        min_fragment=params.min_fragment,
        auto_gap=params.auto_gap,
        idle=params.idle,
    )


def extract_chain(
    log: Log, params: SmcParams, mode: SegmentMode, scene: Scene | None = None
) -> Chain:
    """Temporal, perception and action saliency of one log -> its SMC chain (eq. 40-42).
    ``scene``: the log's (default: rebuilt from its attachments)."""
    warnings: list[str] = []
    name = log.path.name
    scene = scene or scene_of_log(log.attachments, log.path)
    if mode is SegmentMode.markers and not any(m.source == "operator" for m in log.marks):
        warnings.append(
            f"{name}: no saliency marks; the whole log is one fragment (try --segment auto)"
        )
    frags = fragments(log, params, mode, scene.robot)
    if log.truncated or log.interrupted:
        # Only what a boundary closed is a whole fragment: the rest was cut mid-action.
        how = "truncated" if log.truncated else f"interrupted ({log.end.get('reason', '?')})"
        t_end = float(log.poi_t[-1]) if len(log.poi_t) else 0.0
        if frags[-1].cause == "end":
            raise LogError(
                f"{log.path}: {how} at t={t_end:.1f} s before its first fragment "
                "boundary; no complete fragment to compile"
            )
        warnings.append(
            f"{name}: {how} at t={t_end:.1f} s; compiled {len(frags)} complete "
            f"fragment(s) up to t={frags[-1].t1:.1f} s, dropped the last "
            f"{t_end - frags[-1].t1:.1f} s"
        )
    if scene.robot.base is None:
        smc_of = arm_smcs
    else:
        smc_of = mobile_manipulator_smcs if scene.robot.arm_joints else base_smcs
    return Chain(
        log=log.path,
        sha256=log.sha256,
        fragments=tuple(frags),
        smcs=tuple(smc_of(log, frags, scene, params, warnings)),
        warnings=tuple(warnings),
    )


def arm_smcs(
    log: Log, frags: Sequence[Fragment], scene: Scene, params: SmcParams, warnings: list[str]
) -> list[Smc]:
    """The SMCs of an arm's fragments (3.3-3.4): at each decision point the scale's weight
    and the object cluster nearest the POI where the fragment ends (within epsilon); the
    commanded POI path as a DMP, its goal in that object's frame (else the world's).
    Appends to ``warnings`` (crop box, no salient object)."""
    name = log.path.name
    robot = robot_model_of(log)
    has_scale = len(log.weight) > 0
    cut_faces: set[str] = set()
    smcs: list[Smc] = []
    held = 0.0  # symmetry of the object in the hand: nothing yet
    for k, frag in enumerate(frags):
        frame = log.frame_at(frag.t0)
        if frame is None:
            raise LogError(f"{name}: no camera frame near t={frag.t0:.2f} s")
        clusters = clusters_from_frame(frame, geometry_at(robot, log, frame.t), params.perception)
        warnings += crop_warnings(name, frame.t, clusters, params.perception, cut_faces)
        poi_end = log.poi[int(np.argmin(np.abs(log.poi_t - frag.t1)))]
        idx = salient_cluster(clusters, poi_end[:3], params.epsilon)
        cluster = None if idx is None else clusters[idx]
        weight = None
        if has_scale:
            weight = scale_reading(log.weight_t, log.weight, frag.t0, params.weight_window)
        action = _action(log, frag, cluster, held, params)
        if action.event == "close":  # what the hand holds from here on
            held = cluster.yaw_period if cluster is not None else 0.0
        elif action.event == "open":
            held = 0.0
        if cluster is None and action.event != "none":
            warnings.append(
                f"{name}: fragment {k + 1} ({frag.t0:.1f}-{frag.t1:.1f} s) ends "
                f"with no object within {params.epsilon} m of the POI; its goal "
                "is stored in the world frame"
            )
        smcs.append(
            Smc(perception=SalientPerceptions(cluster=cluster, weight=weight), action=action)
        )
    return smcs


def demonstration_warnings(path: Path, scene: Scene) -> tuple[str, ...]:
    """What compile will warn about a demonstration just recorded in ``scene`` (an object
    the crop box cuts, a fragment ending far from any object...), or the one line it would
    refuse it with: said by ``smc record`` while the operator is still there."""
    try:
        log = read_log(path, topics=tp.READ_TOPICS, lazy_frames=True)
        return extract_chain(log, scene_params(scene), SegmentMode.markers, scene).warnings
    except SmcError as e:
        return (f"compile would refuse it: {e}",)


def _action(
    log: Log, frag: Fragment, cluster: Cluster | None, held_symmetry: float, params: SmcParams
) -> Action:
    """Action saliency (3.4): the commanded POI path over the fragment as a DMP, its goal
    and approach in the salient object's frame; ``held_symmetry`` is that of the object in
    the hand (see :class:`smccli.learn.smc.Action`)."""
    cmds = fragment_commands(log, frag)
    t = np.array([c.t for c in cmds]) - cmds[0].t
    path = np.array([c.target for c in cmds], dtype=float)
    grip = np.array([c.gripper for c in cmds])
    if params.idle.squeeze:  # the DMP and the gripper phase on the clock of the motion
        idle = idle_centres(t, path, grip, None, params.idle)
        t = active_times(t, idle, params.idle, keep=params.idle.keep)
    return action_from_path(t, path, grip, cluster, params, held_symmetry=held_symmetry)


def required_topics(log: Log, scene: Scene | None = None) -> set[str]:
    """The topics compile needs in ``log`` (its scene's robot decides: an arm, a base, a
    mobile manipulator; default: the scene the log carries, else an arm's)."""
    if scene is None:  # doctor: the log's own scene, if it can be rebuilt
        try:
            scene = scene_of_log(log.attachments, log.path)
        except LogError:
            scene = None
    if scene is not None and scene.robot.base is not None:
        if scene.robot.arm_joints:  # a mobile manipulator: both, and its base pose
            return set(tp.BASE_TOPICS | tp.ARM_TOPICS | {tp.BASE})
        return set(tp.BASE_TOPICS)
    needed = set(tp.ARM_TOPICS)
    if log.metadata.get("has_scale") == "true":
        needed.add("/scale/weight")
    return needed


def scene_params(scene: Scene, overrides: Sequence[str] = ()) -> SmcParams:
    """The parameters a new tree of ``scene`` starts with: the defaults, the scene's
    perception settings (scene.yaml ``perception``: a mobile manipulator's crop box in its
    base's frame), then ``overrides`` (``--set``)."""
    params = replace(SmcParams(), perception=scene_perception(scene))
    return with_overrides(params, list(overrides))
