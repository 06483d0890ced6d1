"""``smc record``: record a demonstration (or a session of them) and say what it holds."""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape
from rich.progress import TextColumn, TimeElapsedColumn
from rich.table import Table

from smccli.commands.console import err, live, one_line, out, say, warn

if TYPE_CHECKING:
    from smccli.record.session import RecordSummary
    from smccli.world.scene import Scene


class OperatorKind(str, Enum):
    script = "script"
    keyboard = "keyboard"


def record(
    scene: Annotated[str, typer.Option(help="Built-in scene name or path to a scene.yaml.")],
    operator: Annotated[
        OperatorKind, typer.Option(help="Who drives the robot.")
    ] = OperatorKind.script,
    script: Annotated[
        Path | None,
        typer.Option(help="Teleop script (YAML) for --operator script.", dir_okay=False),
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the operator's noise and of the layout.")] = 0,
    output: Annotated[Path, typer.Option("-o", "--output", help="Log to write (.mcap).")] = Path(
        "demo.mcap"
    ),
    force: Annotated[bool, typer.Option(help="Overwrite an existing log.")] = False,
    randomize: Annotated[
        bool, typer.Option(help="Start from a random layout (else nominal).")
    ] = False,
    realtime: Annotated[bool, typer.Option(help="Pace the script operator at real time.")] = False,
    episodes: Annotated[
        int,
        typer.Option(
            min=1,
            help="Demonstrations in one session: NAME-000.mcap, NAME-001.mcap, ... (keyboard: "
            "Enter keeps one and goes on, X records it again, Esc ends the session).",
        ),
    ] = 1,
    allow_failed: Annotated[
        bool,
        typer.Option(
            help="Exit 0 when a demonstration fails its scene's task (one meant to fail, "
            "e.g. to teach a recovery); without it such a recording is kept and smc exits 1.",
        ),
    ] = False,
) -> None:
    """Record a demonstration (or a session of them) into MCAP logs.

    Exit 1 when a demonstration failed its scene's task (the log is kept), 130 when
    interrupted (the log is kept, marked interrupted), 2 on bad input (no log)."""
    from smccli.record.session import RecordConfig, record_episodes

    cfg = RecordConfig(
        scene=scene,
        operator=operator.value,
        script=script,
        seed=seed,
        output=output,
        force=force,
        randomize=randomize,
        realtime=realtime,
        episodes=episodes,
    )
    with live(
        TextColumn("[bold]recording[/]"),
        TextColumn("{task.description}"),
        TimeElapsedColumn(),
    ) as progress:
        task = progress.add_task("", total=None)
        next_line = [1.0]

        def status(s) -> None:
            text = (
                f"sim {s.t:6.2f} s  on disk {s.t_on_disk:6.2f} s  msgs {s.messages}  "
                f"marks {s.marks}"
            )
            progress.update(task, description=text)
            if not err.is_terminal and s.t >= next_line[0]:
                # No live bar off a terminal: a plain line per simulated second, so logs
                # and supervisors see how far the recording got and what is safe on disk.
                say(f"recording: {text}")
                next_line[0] += 1.0

        summaries = record_episodes(cfg, on_status=status, on_message=say)
    _report(summaries, scene, allow_failed)


def _report(summaries: list[RecordSummary], scene: str, allow_failed: bool) -> None:
    """Print what each log holds; exit 130 when the session was interrupted, 1 when a
    demonstration failed its task (without ``allow_failed``)."""
    from smccli.world.scene import load_scene

    recorded_in = summaries[-1].scene or load_scene(scene)
    for summary in summaries:
        _print_summary(summary, recorded_in, allow_failed)
    summary = summaries[-1]
    if summary.interrupted:
        say(
            f"interrupted ({summary.interrupted}): kept {summary.path} with "
            f"{summary.duration:.1f} s, marked interrupted in its metadata"
        )
        raise typer.Exit(130)
    if not allow_failed and any(s.failed_task for s in summaries):
        # Scripts and CI see in the exit code what a person sees in the verdict line;
        # the recording stays (a failed demonstration is evidence, and --allow-failed
        # keeps the ones meant to fail).
        raise typer.Exit(1)


def _print_summary(summary: RecordSummary, scene: Scene, allow_failed: bool) -> None:
    out.print(
        f"[bold green]wrote[/] {escape(str(summary.path))}  ({summary.size_bytes / 1e6:.2f} MB, "
        f"{summary.duration:.1f} s, {summary.fragments} fragment(s) marked)"
    )
    table = Table("topic", "messages", "rate [Hz]")
    for topic, (count, rate) in sorted(summary.topics.items()):
        table.add_row(topic, str(count), f"{rate:.1f}")
    out.print(table)
    task = summary.task or {}
    if task.get("success") is True:
        out.print("[green]task achieved[/]")
    elif summary.failed_task:
        failed = f"{summary.path}: the demonstration failed its task ({task.get('reason')})"
        if allow_failed or summary.interrupted:
            warn(failed)
        else:
            err.print(
                f"[bold red]error:[/] {one_line(failed)}; the recording is kept (record it "
                "again, or --allow-failed for a demonstration meant to fail)",
                highlight=False,
                soft_wrap=True,
            )
    if summary.interrupted is None:  # what compile will say about it, said now
        from smccli.learn.chain import demonstration_warnings

        for warning in demonstration_warnings(summary.path, scene):
            warn(warning)
