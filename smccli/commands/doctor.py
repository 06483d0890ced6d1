"""``smc doctor``: a table of checks per log, and the repair of a truncated one."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.table import Table

from smccli.commands.console import TopicsOption, out
from smccli.errors import SmcError


def doctor(
    logs: Annotated[
        list[Path],
        typer.Argument(
            help="Logs to check: smc's .mcap (or a killed recorder's .part), or with --topics "
            "bags (a rosbag2 folder, sqlite3 or MCAP storage; a ROS 2 .mcap; a ROS 1 .bag)."
        ),
    ],
    repair: Annotated[
        Path | None,
        typer.Option(help="Write LOG's whole chunks as a valid, indexed MCAP (one LOG only)."),
    ] = None,
    force: Annotated[bool, typer.Option(help="Overwrite the --repair output.")] = False,
    topics: TopicsOption = None,
) -> None:
    """Check logs before compiling: exit 0 healthy, 1 warnings, 2 a log compile would reject."""
    from smccli.learn import doctor as dr
    from smccli.logs.ros2_bag import load_topic_map

    if repair is not None and len(logs) != 1:
        raise SmcError(f"--repair takes exactly one LOG, got {len(logs)}")
    if repair is not None and topics is not None:
        raise SmcError("--repair rewrites smc logs, not ROS 2 bags (--topics)")
    topic_map = None if topics is None else load_topic_map(topics)
    fixed = dr.repair(logs[0], repair, force=force) if repair is not None else None
    diagnoses = [dr.diagnose(p, topic_map) for p in logs] + (
        [dr.diagnose(fixed.path)] if fixed else []
    )
    colour = {"ok": "green", "warn": "yellow", "error": "bold red"}
    for d in diagnoses:
        title = f"{escape(str(d.path))}: [{colour[d.status]}]{d.status}[/]"
        table = Table("check", "status", "detail", title=title, title_justify="left")
        for c in d.checks:
            table.add_row(escape(c.name), f"[{colour[c.status]}]{c.status}[/]", escape(c.detail))
        out.print(table)
    if fixed is not None:
        what = (
            f"the {fixed.messages} messages of its {fixed.chunks} whole chunks"
            if fixed.truncated
            else f"it was not truncated, copied all {fixed.messages} messages"
        )
        out.print(
            f"[bold green]repaired[/] {escape(str(logs[0]))} -> {escape(str(fixed.path))}: {what}",
            highlight=False,
        )
    # With --repair the code is the repaired file's: that is the log the user goes on with.
    raise typer.Exit(dr.exit_code(diagnoses[-1:] if fixed else diagnoses))
