"""The ``smc`` command line: the app that assembles the commands of :mod:`smccli.commands`,
and the entry point that maps SmcError to exit codes.

Every command parses its options, calls one library function and prints what it returns;
nothing here knows how the work is done.
"""

from __future__ import annotations

import os
import sys
import warnings
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.table import Table

from smccli.commands import (
    catalog,
    compile,
    doctor,
    export,
    inspect,
    record,
    replay,
    ros,
    verify,
)
from smccli.commands.console import err, one_line, out, say, warn
from smccli.errors import SmcError

os.environ.setdefault("MUJOCO_GL", "egl")

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Teach a robot a task from a few demonstrations (Sensory-Motor "
    "Contingencies, Stefanini et al. 2024).",
)
# In the order `smc --help` lists them.
app.command()(catalog.scenes)
app.command()(catalog.robots)
app.command()(record.record)
app.command("compile")(compile.compile_cmd)
app.command()(verify.verify)
app.command()(replay.replay)
app.command()(inspect.inspect)
app.command()(doctor.doctor)
app.command()(ros.run)
app.command()(ros.sim)


@app.command("topics")
def topics_command(
    bag: Annotated[
        Path,
        typer.Argument(help="A bag: rosbag2 directory (MCAP or sqlite3), .mcap or ROS 1 .bag."),
    ],
    output: Annotated[
        Path | None,
        typer.Option("-o", "--output", help="Write the draft topic map here (YAML) to edit."),
    ] = None,
    scene: Annotated[
        str | None,
        typer.Option(
            help="The scene the bag was recorded in (name or scene.yaml): fills in the map's "
            "scene and matches the driver's joint names to its robot's."
        ),
    ] = None,
    force: Annotated[bool, typer.Option(help="Overwrite an existing --output.")] = False,
) -> None:
    """What a bag holds (topics, types, counts, rates, TF frames) and a draft topic map."""
    from smccli.logs.bag_topics import bag_contents, draft_topic_map
    from smccli.outputs import check_output, write_atomic

    if output is not None:
        check_output(output, force=force)
    contents = bag_contents(bag)
    table = Table(
        "topic",
        "type",
        "messages",
        "Hz",
        "first message",
        title=f"{escape(str(bag))}: {contents.duration_s:.1f} s",
        title_justify="left",
    )
    for t in contents.topics:
        table.add_row(escape(t.topic), t.type, str(t.count), f"{t.rate_hz:.1f}", escape(t.detail))
    out.print(table)
    if contents.frames:
        links = [f"{p} -> {c}{' (static)' if s else ''}" for p, c, s in contents.frames]
        out.print("TF frames: " + escape(", ".join(links)), highlight=False)
    draft = draft_topic_map(contents, scene)
    if output is None:
        out.print(escape(draft.text()), highlight=False)
        return
    write_atomic(output, draft.text())
    out.print(
        f"[bold green]wrote[/] {escape(str(output))}: {escape(', '.join(draft.todo()))}, then "
        f"`smc doctor {escape(str(bag))} --topics {escape(str(output))}`",
        highlight=False,
    )


app.command()(export.export)


_WARNED: set[str] = set()


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ANN001
    """A Python warning as smc's own ``warning: ...`` line (not Python's two lines), once:
    a model composed several times warns each time."""
    if str(message) not in _WARNED:
        _WARNED.add(str(message))
        warn(str(message))


def main() -> None:
    """Entry point: run the app; expected failures become one line and an exit code."""
    warnings.showwarning = _one_line_warning
    try:
        app()
    except SmcError as exc:
        # One line, whatever the message holds: scripts and CI grep for it.
        err.print(f"[bold red]error:[/] {one_line(str(exc))}", highlight=False, soft_wrap=True)
        sys.exit(exc.exit_code)
    except KeyboardInterrupt:
        say("interrupted")
        sys.exit(130)


if __name__ == "__main__":
    main()
