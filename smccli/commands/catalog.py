"""``smc scenes`` and ``smc robots``: the built-in scenes and robots (and the user's own),
checked and listed."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape
from rich.table import Table

from smccli.commands.console import err, one_line, out

if TYPE_CHECKING:
    from smccli.world.robot import Robot
    from smccli.world.scene import Scene


def scenes(
    files: Annotated[
        list[Path] | None,
        typer.Argument(help="Scene files of your own (scene.yaml) to check and list too."),
    ] = None,
) -> None:
    """List the built-in scenes (and check your own): robot, objects, variants, sensors."""
    from smccli.world.scene import list_scenes, load_scene

    found = list_scenes() + [load_scene(f) for f in files or []]
    table = Table("scene", "robot", "objects", "variants", "sensors", "task")
    for s in found:
        sensors = [f"camera {s.camera.width}x{s.camera.height} @ {s.camera.rate:g} Hz"]
        if s.scale:
            sensors.append(f"scale ({s.scale})")
        variants = "; ".join(f"{v}: {', '.join(o)}" for v, o in s.variants) or "-"
        objects = ", ".join(o.name for o in s.objects)
        row = (s.name, s.robot.name, objects, variants, ", ".join(sensors), s.description)
        table.add_row(*(escape(x) for x in row))
    out.print(table)


def robots(
    files: Annotated[
        list[Path] | None,
        typer.Argument(help="Robot files of your own (robot.yaml) to check and list too."),
    ] = None,
    scene: Annotated[
        str | None,
        typer.Option(
            help="Check the robot of this scene (built-in name or scene.yaml) in it: its "
            "object ranges and its camera too. With `import`: a copy holding the drafted "
            "robot is written to DIR/scene.yaml and the draft checked in it.",
        ),
    ] = None,
    gripper: Annotated[
        Path | None,
        typer.Option(help="`smc robots import ARM`: the gripper's own MJCF, if separate."),
    ] = None,
    output: Annotated[
        Path | None,
        typer.Option("--output", "-o", help="`smc robots import ARM`: the folder to write."),
    ] = None,
    force: Annotated[
        bool, typer.Option(help="`smc robots import`: overwrite DIR/robot.yaml.")
    ] = False,
) -> None:
    """List the built-in robots (and check your own): degrees of freedom, gripper, sensors.

    A robot file given, or a scene's robot, is also run in simulation (gripper, home
    posture, reach, POI); exit 2 when a check fails.

    `smc robots import ARM [--gripper GRIPPER] -o DIR` drafts DIR/robot.yaml for a
    vendor's arm (MJCF or URDF) and gripper (MJCF), never editing them, prints what it
    guessed and why, then checks the draft as above."""
    from smccli.world.robot import list_robots, load_robot
    from smccli.world.scene import load_scene

    if files and files[0] == Path("import"):
        _import(files[1:], gripper, output, force, scene)
        return
    if gripper is not None or output is not None:
        raise typer.BadParameter("--gripper and -o are for `smc robots import ARM`")
    mine = [load_robot(f) for f in files or []]
    in_scene = load_scene(scene) if scene is not None else None
    found = list_robots() + mine
    listed = {r.path for r in found}
    if in_scene is not None and in_scene.robot.path not in listed:
        found.append(in_scene.robot)
    table = Table("robot", "DoF", "gripper", "sensors", "description")
    for r in found:
        table.add_row(*(escape(x) for x in _robot_row(r)))
    out.print(table)
    benches: list[tuple[Robot, Scene | None]] = [
        (r, None) for r in mine if in_scene is None or r.path != in_scene.robot.path
    ]
    if in_scene is not None:
        benches.append((in_scene.robot, in_scene))
    failed = []
    for robot, where in benches:
        failed += _simulation_checks(robot, where)
    for line in failed:
        err.print(f"[bold red]error:[/] {one_line(line)}", highlight=False, soft_wrap=True)
    if failed:
        raise typer.Exit(2)


def _robot_row(r: Robot) -> tuple[str, ...]:
    """A robot's row in ``smc robots``' table."""
    g = r.gripper
    gripper = (
        "none"
        if g is None
        else f"{len(g.joints)} finger{'s' if len(g.joints) != 1 else ''}, "
        f"{g.closed:g}-{g.open:g} per finger ({g.actuator})"
    )
    mounted = [f"{s.type} {s.name}" for s in r.sensors]
    sensors = ", ".join(["joint encoders", *mounted])
    dof = f"{r.dof}" + (" (base 3)" if r.base else "")
    return (r.name, dof, gripper, sensors, r.description)


_SHOWN = {"pass": "[green]pass[/]", "fail": "[bold red]FAIL[/]", "skip": "[dim]skip[/]"}


def _simulation_checks(robot: Robot, scene: Scene | None) -> list[str]:
    """Run and print the simulation checks of ``robot`` (in ``scene``, else alone on a
    table); one line per failed check, naming the file to change."""
    from smccli.world.robot_checks import simulation_checks

    findings = simulation_checks(robot, scene)
    robot_file = str(robot.path or robot.name)
    where = f"in scene {scene.name}" if scene is not None else "alone on a table"
    table = Table(
        "check", "result", "measured", "fix", title=f"{escape(robot_file)} {escape(where)}"
    )
    for f in findings:
        table.add_row(f.check, _SHOWN[f.status], escape(f.measured), escape(f.fix))
    out.print(table)
    lines = []
    for f in findings:
        if f.status == "fail":
            # Ranges are the scene file's; everything else is the robot file's (or its MJCF's).
            file = (
                str(scene.yaml_path or scene.name) if f.check == "reach" and scene else robot_file
            )
            lines.append(f"{file}: {f.check}: {f.measured}; {f.fix}")
    return lines


def _import(
    args: list[Path], gripper: Path | None, output: Path | None, force: bool, scene: str | None
) -> None:
    """``smc robots import``: draft, write, print the guesses, run the checks."""
    from smccli.outputs import check_output, write_atomic
    from smccli.world.robot import load_robot
    from smccli.world.robot_import import draft_robot, scene_text, write_draft
    from smccli.world.scene import load_scene

    if len(args) != 1 or output is None:
        raise typer.BadParameter("usage: smc robots import ARM [--gripper GRIPPER] -o DIR")
    copy = scene_text(scene, output) if scene is not None else None
    draft = draft_robot(args[0], gripper, output)
    if copy is not None:  # both refused before either is written
        output.mkdir(parents=True, exist_ok=True)
        check_output(output / "scene.yaml", force=force)
    path = write_draft(draft, output, force=force)
    if copy is not None:
        scene = str(write_atomic(output / "scene.yaml", copy))
        out.print(f"{escape(scene)}: a copy of the scene holding the drafted robot")
    table = Table("what", "value", "why", title=f"{escape(str(path))}: what was guessed")
    for g in draft.guesses:
        table.add_row(escape(g.what), escape(g.value), escape(g.why))
    out.print(table)
    robot = load_robot(path)
    where = load_scene(scene) if scene is not None else None
    failed = _simulation_checks(robot, where)
    for line in failed:
        err.print(f"[bold red]error:[/] {one_line(line)}", highlight=False, soft_wrap=True)
    if failed:
        raise typer.Exit(2)
