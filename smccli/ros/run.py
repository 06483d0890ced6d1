"""The library behind ``smc run --ros1`` (:func:`run_ros1`) and ``smc sim --ros1``
(:func:`sim_ros1`): load the tree, scene and topic map, start the ROS 1 layer, handle
Ctrl-C and SIGTERM, write the reports."""

from __future__ import annotations

import json
import signal
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml

from smccli.errors import SceneError, SmcError
from smccli.logs.topic_map import TopicMap, load_topic_map, parse_topic_map
from smccli.outputs import check_output, write_atomic
from smccli.ros.node import NodeResult, run_node
from smccli.ros.sim_robot import SimRobot, sim_topic_map


def run_map(topics: Path) -> TopicMap:
    """The topic map of a run; SceneError (exit 2) when it has no ``run`` section."""
    m = load_topic_map(topics)
    if m.run is None:
        raise SceneError(
            f"{topics}: no `run:` section: smc run needs run.command (the POI's "
            "geometry_msgs/PoseStamped target topic) or run.arm (the arm's "
            "trajectory_msgs/JointTrajectory) and, with a gripper, run.gripper"
        )
    return m


def run_ros1(
    tree_path: Path,
    topics: Path,
    *,
    report: Path | None = None,
    force: bool = False,
    max_time: float = 300.0,
    look_period: float | None = None,
) -> NodeResult:
    """``smc run TREE --ros1 --topics MAP``: the tree drives the robot the map describes
    (:func:`smccli.ros.node.run_node`) until a leaf or a stop; Ctrl-C stops it
    (``interrupted``). SmcError (exit 2) for a bad tree, map or scene, or without rospy."""
    from smccli.execute.episode import resolve
    from smccli.ros.ros1 import Ros1Node

    m = run_map(topics)
    assert m.run is not None
    if report is not None:
        check_output(report, force=force)
    tree, scene = resolve(tree_path, m.scene)
    if scene.robot.base is not None and scene.robot.arm_joints:
        raise SmcError(
            f"{topics}: scene {scene.name}: smc run drives an arm or a mobile base; a mobile "
            "manipulator (two POIs) is not supported yet"
        )
    bus = Ros1Node(m, scene.robot, m.run.wait_s)

    def interrupt(signum: int, frame: Any) -> None:
        bus.interrupted = True

    previous = signal.signal(signal.SIGINT, interrupt)
    try:
        result = run_node(tree, scene, m, bus, max_time=max_time, look_period=look_period)
    finally:
        signal.signal(signal.SIGINT, previous)
        bus.close()
    if report is not None:
        doc = {"tree": str(tree_path), "topics": str(topics), **result.to_report()}
        write_atomic(report, json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return result


def sim_ros1(
    scene_name: str,
    *,
    seed: int = 0,
    layout: Path | None = None,
    topics: Path | None = None,
    report: Path | None = None,
    force: bool = False,
    on_ready: Callable[[TopicMap], None] | None = None,
    write_map: Path | None = None,
) -> dict[str, Any]:
    """``smc sim --ros1 --scene S``: the scene as a ROS robot (:class:`SimRobot`) on the
    layout file or the seed's layout (as ``smc replay``'s), on the topics of ``topics``
    (default :func:`~smccli.ros.sim_robot.sim_topic_map`), until Ctrl-C or SIGTERM; then
    the scene settles and is scored. Returns the verdict (written to ``report``).
    ``write_map``: where to write the default map (the one ``smc run`` then takes)."""
    from smccli.execute.episode import layout_for
    from smccli.ros.ros1 import Ros1Sim
    from smccli.world.layout import load_layout_file
    from smccli.world.scene import load_scene

    for out in (report, write_map):
        if out is not None:
            check_output(out, force=force)
    scene = load_scene(scene_name)
    lay = load_layout_file(layout, scene) if layout is not None else layout_for(scene, seed)
    if topics is not None:
        m = load_topic_map(topics)
    else:
        data = sim_topic_map(scene)
        m = parse_topic_map(data)
        if write_map is not None:
            write_atomic(write_map, yaml.safe_dump(data, sort_keys=False))
    if m.run is None:
        raise SceneError(f"{topics}: no `run:` section: the sim takes its commands there")
    robot = SimRobot(scene, lay, m)
    try:
        ros = Ros1Sim(robot)

        def stop(signum: int, frame: Any) -> None:
            ros.stopped.set()

        previous = [signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)]
        try:
            if on_ready is not None:
                on_ready(m)
            ros.spin()
        finally:
            signal.signal(signal.SIGINT, previous[0])
            signal.signal(signal.SIGTERM, previous[1])
            ros.close()
        verdict = robot.score()
    finally:
        robot.close()
    verdict["seed"] = seed
    if report is not None:
        write_atomic(report, json.dumps(verdict, indent=1, allow_nan=False) + "\n")
    return verdict
