"""``smc export``: a log as a ROS 2 bag, with the topic map that reads it back."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from smccli.commands.console import out, warn
from smccli.errors import SmcError


def export(
    log: Annotated[Path, typer.Argument(help="Native smc log (.mcap) to export.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Bag to write (.mcap).")],
    ros2: Annotated[
        bool, typer.Option("--ros2", help="As a ROS 2 bag (MCAP, CDR); the only format so far.")
    ] = False,
    force: Annotated[bool, typer.Option(help="Overwrite an existing output.")] = False,
    topics: Annotated[
        Path | None,
        typer.Option(
            help="Where to write the bag's topic map (for smc compile --topics); "
            "default: BAG with the suffix .topics.yaml.",
            dir_okay=False,
        ),
    ] = None,
) -> None:
    """Export a log for other tools: --ros2 writes a ROS 2 bag (MCAP storage, CDR messages)
    and the topic map that reads it back."""
    import yaml

    from smccli.logs.ros2_export import export_ros2
    from smccli.outputs import check_output, write_atomic

    if not ros2:
        raise SmcError("choose the output format: --ros2 (the only one so far)")
    topics = topics or output.with_suffix(".topics.yaml")
    check_output(topics, force=force)
    summary = export_ros2(
        log,
        output,
        force=force,
        on_warning=warn,
    )
    out.print(
        f"[bold green]wrote[/] {escape(str(summary.out))}  (ROS 2 bag, "
        f"{summary.size_bytes / 1e6:.2f} MB from {summary.source_bytes / 1e6:.2f} MB, "
        f"{sum(summary.messages.values())} messages)",
        highlight=False,
    )
    width = max(map(len, summary.messages), default=0)
    for topic, count in summary.messages.items():  # plain lines: names are never cut
        out.print(
            f"  {escape(topic):<{width}}  {count:>6}  {summary.types[topic]}",
            highlight=False,
            soft_wrap=True,
        )
    if summary.skipped:
        skipped = ", ".join(f"{t} ({n})" for t, n in sorted(summary.skipped.items()))
        out.print(f"not exported: {escape(skipped)}", highlight=False)
    head = "# Topic map of an exported bag (schemas/topic_map.schema.json)\n"
    write_atomic(topics, head + yaml.safe_dump(summary.topic_map(), sort_keys=False))
    out.print(f"[bold green]wrote[/] {escape(str(topics))}  (its topic map)", highlight=False)
