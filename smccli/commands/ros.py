"""``smc run`` (the tree drives a robot over ROS 1) and ``smc sim`` (a scene as a ROS 1
robot for it): parse the options, call :mod:`smccli.ros.run`, print how it ended."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape

from smccli.commands.console import out, say
from smccli.errors import SmcError

if TYPE_CHECKING:
    from smccli.logs.topic_map import TopicMap

Ros1Option = Annotated[bool, typer.Option("--ros1", help="Over ROS 1 (rospy; a roscore runs).")]
MapOption = Annotated[
    Path | None,
    typer.Option(
        "--topics",
        help="Topic map (YAML, schemas/topic_map.schema.json) with a `run:` section.",
        dir_okay=False,
    ),
]


def _middleware(ros1: bool) -> None:
    if not ros1:
        raise SmcError("say which middleware: --ros1 (the only one so far)")


def run(
    tree: Annotated[Path, typer.Argument(help="Tree file (tree.json).")],
    ros1: Ros1Option = False,
    topics: MapOption = None,
    report: Annotated[Path | None, typer.Option(help="Report (JSON): decisions, latency.")] = None,
    max_time: Annotated[
        float, typer.Option(help="Stop after this long on the robot's clock, in seconds.")
    ] = 300.0,
    force: Annotated[bool, typer.Option(help="Overwrite the report.")] = False,
) -> None:
    """Run the tree on a robot: its sensors in, POI and gripper commands out, each decision
    on /smc/decision. Exit 0 leaf reached, 1 no contingent SMC, 3 target unreachable,
    4 stale sensors, 5 TF lost, 6 timeout, 130 Ctrl-C."""
    from smccli.ros.run import run_ros1

    _middleware(ros1)
    if topics is None:
        raise SmcError("smc run needs --topics MAP: which topics the robot reads and takes")
    result = run_ros1(tree, topics, report=report, force=force, max_time=max_time)
    for d in result.decisions:
        goal = (
            "" if d.mapped_goal is None else " goal " + ", ".join(f"{v:.3f}" for v in d.mapped_goal)
        )
        out.print(
            f"t={d.t:.2f} s {escape(d.nodes[0])} -> {escape(d.chosen or 'none')}{goal}",
            highlight=False,
        )
    colour = "green" if result.outcome == "success" else "bold red"
    out.print(f"[{colour}]{result.outcome}[/]: {escape(result.reason)}", highlight=False)
    raise typer.Exit(result.exit_code)


def sim(
    ros1: Ros1Option = False,
    scene: Annotated[str, typer.Option(help="Scene name or path of a scene.yaml.")] = "bench_pick",
    seed: Annotated[int, typer.Option(help="Seed of the layout (as smc replay's).")] = 0,
    layout: Annotated[
        Path | None, typer.Option(help="Layout file (object -> [x, y, z, yaw]).", dir_okay=False)
    ] = None,
    topics: MapOption = None,
    report: Annotated[Path | None, typer.Option(help="Verdict at the end (JSON).")] = None,
    write_map: Annotated[
        Path | None,
        typer.Option(help="Write the topic map it serves (for smc run --topics).", dir_okay=False),
    ] = None,
    force: Annotated[bool, typer.Option(help="Overwrite the report and the map.")] = False,
) -> None:
    """Simulate a scene as a ROS robot (camera, joints, TF, lidar) that executes POI and
    gripper commands, until Ctrl-C or SIGTERM; then score the task."""
    from smccli.ros.run import sim_ros1

    _middleware(ros1)

    def ready(m: TopicMap) -> None:
        assert m.run is not None
        topics = ", ".join(t for t in (m.run.command, m.run.arm, m.run.gripper) if t)
        say(f"sim: {scene} running, commands on {escape(topics)}")

    verdict = sim_ros1(
        scene,
        seed=seed,
        layout=layout,
        topics=topics,
        report=report,
        force=force,
        on_ready=ready,
        write_map=write_map,
    )
    colour = "green" if verdict["success"] else "bold red"
    ok = "success" if verdict["success"] else "failure"
    out.print(f"[{colour}]{ok}[/]: {escape(verdict['reason'])}", highlight=False)
