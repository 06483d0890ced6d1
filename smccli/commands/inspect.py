"""``smc inspect``: the tree and the traces in Rerun."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from smccli.commands.console import TopicsOption, out, warn
from smccli.errors import SmcError


def inspect(
    tree: Annotated[Path, typer.Argument(help="Tree file (tree.json).")],
    logs: Annotated[list[Path] | None, typer.Argument(help="Demonstration or replay logs.")] = None,
    save: Annotated[Path | None, typer.Option(help="Write a Rerun recording (.rrd).")] = None,
    spawn: Annotated[bool, typer.Option(help="Open Rerun's native viewer.")] = False,
    serve: Annotated[bool, typer.Option(help="Serve Rerun's web viewer on 127.0.0.1.")] = False,
    port: Annotated[int, typer.Option(help="Web viewer port (with --serve).")] = 9090,
    grpc_port: Annotated[
        int | None,
        typer.Option(help="Data (gRPC) port the page reads from (with --serve; default: free)."),
    ] = None,
    force: Annotated[bool, typer.Option(help="Overwrite an existing --save file.")] = False,
    topics: TopicsOption = None,
) -> None:
    """Show the tree and the traces in Rerun."""
    from smccli.inspect import recording as ins
    from smccli.logs.ros2_bag import load_topic_map

    topic_map = None if topics is None else load_topic_map(topics)

    if sum([save is not None, spawn, serve]) > 1:
        raise SmcError("choose one of --save, --spawn, --serve")
    if grpc_port is not None and not serve:
        raise SmcError("--grpc-port goes with --serve")
    if not (spawn or serve) and save is None:
        save = tree.with_suffix(".rrd")
    result = ins.inspect(
        tree,
        logs or [],
        save=save,
        spawn=spawn,
        serve=serve,
        port=port,
        grpc_port=grpc_port,
        force=force,
        on_warning=warn,
        on_message=lambda m: out.print(escape(m), highlight=False, soft_wrap=True),
        topic_map=topic_map,
    )
    if result.rrd is not None:
        out.print(
            f"[bold green]wrote[/] {escape(str(result.rrd))}  ({len(result.recordings)} "
            f"recording(s): {', '.join(result.recordings)}; open with `rerun {result.rrd}`)",
            highlight=False,
        )
