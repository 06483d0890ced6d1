"""What every command shares: the two consoles, one-line messages on stderr, a progress
display, and the ``--topics`` option."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import Progress

out = Console(soft_wrap=True)  # a line is never cut: paths stay whole in logs and pipes
err = Console(stderr=True)


def one_line(text: str) -> str:
    """``text`` on one line, escaped for rich: its whitespace runs (newlines too) collapsed."""
    return escape(" ".join(str(text).split()))


def say(text: str) -> None:
    """A line on stderr, never wrapped: off a terminal (CI, pipes, log files) rich would
    wrap it at 80 columns, cutting file paths in two."""
    err.print(one_line(text), highlight=False, soft_wrap=True)


def warn(text: str) -> None:
    """``warning: ...`` on one line of stderr."""
    err.print(f"[yellow]warning:[/] {one_line(text)}", highlight=False, soft_wrap=True)


def live(*columns, **kwargs) -> Progress:
    """A transient progress display on stderr, only on a terminal: off one, it would leave
    a blank line behind (and logs get plain status lines instead)."""
    return Progress(*columns, console=err, transient=True, disable=not err.is_terminal, **kwargs)


TopicsOption = Annotated[
    Path | None,
    typer.Option(
        help="The logs are bags (ROS 2, or ROS 1 .bag): read them through this topic map "
        "(schemas/topic_map.schema.json).",
        dir_okay=False,
    ),
]
"""``--topics MAP``, shared by compile, doctor and inspect."""
