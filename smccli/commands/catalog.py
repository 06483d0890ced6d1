"""``smc scenes`` and ``smc robots``: the built-in scenes and robots (and the user's own),
checked and listed."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.table import Table

from smccli.commands.console import out


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
) -> None:
    """List the built-in robots (and check your own): degrees of freedom, gripper, sensors."""
    from smccli.world.robot import list_robots, load_robot

    found = list_robots() + [load_robot(f) for f in files or []]
    table = Table("robot", "DoF", "gripper", "sensors", "description")
    for r in found:
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
        table.add_row(*(escape(x) for x in (r.name, dof, gripper, sensors, r.description)))
    out.print(table)
