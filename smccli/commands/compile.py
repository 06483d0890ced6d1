"""``smc compile``: logs into the tree, with progress, then the tree as text."""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, TextColumn

from smccli.commands.console import TopicsOption, live, out, say, warn

if TYPE_CHECKING:
    from smccli.learn.tree import Tree as LearnedTree


class SegmentChoice(str, Enum):
    markers = "markers"
    auto = "auto"
    both = "both"


def compile_cmd(
    logs: Annotated[
        list[Path],
        typer.Argument(
            help="Demonstration logs: smc's .mcap logs, or with --topics bags (a rosbag2 "
            "folder, sqlite3 or MCAP storage; a ROS 2 .mcap; a ROS 1 .bag)."
        ),
    ],
    output: Annotated[Path, typer.Option("-o", "--output", help="Tree file.")] = Path("tree.json"),
    segment: Annotated[
        SegmentChoice, typer.Option(help="Where fragment boundaries come from.")
    ] = SegmentChoice.markers,
    rebuild: Annotated[
        bool, typer.Option(help="Start a new tree instead of adding to it.")
    ] = False,
    set_: Annotated[
        list[str] | None,
        typer.Option(
            "--set", help="Override a parameter: KEY=VALUE (e.g. t_hp=0.12, dmp.n_basis=50)."
        ),
    ] = None,
    topics: TopicsOption = None,
    workers: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="Processes reading the logs in parallel (default: one per core, at most one "
            "per log, none below 6 logs; 1: none). The tree is the same.",
        ),
    ] = None,
    strict: Annotated[
        bool,
        typer.Option(help="Refuse a demonstration that failed its task (default: a warning)."),
    ] = False,
) -> None:
    """Segment logs, extract SMCs and merge them into a versioned tree.json."""
    from smccli.learn.compile import compile_logs
    from smccli.learn.segmentation import SegmentMode
    from smccli.logs.ros2_bag import load_topic_map

    topic_map = None if topics is None else load_topic_map(topics)

    with live(
        TextColumn("[bold]compiling[/]"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.description}"),
    ) as progress:
        task = progress.add_task("", total=len(logs))
        seen: set[Path] = set()

        def on_progress(path: Path, stage: str) -> None:
            if stage == "reading" and path not in seen:
                if seen:
                    progress.advance(task)
                seen.add(path)
            progress.update(task, description=f"{path.name}: {stage}")

        result = compile_logs(
            logs,
            output,
            segment_mode=SegmentMode(segment.value),
            rebuild=rebuild,
            overrides=set_ or [],
            on_progress=on_progress,
            on_warning=warn,
            topic_map=topic_map,
            workers=workers,
            strict=strict,
        )
        progress.update(task, completed=len(logs))
    for p in result.skipped:
        say(f"skipped {p} (already in the tree)")
    state = f"version {result.tree.version}" + ("" if result.changed else " (unchanged)")
    out.print(
        f"[bold green]{output}[/]: {state}, {len(result.tree.nodes)} nodes, "
        f"{len(result.tree.edges)} edges"
    )
    _print_tree(result.tree)


def _print_tree(tree: LearnedTree) -> None:
    """Nodes and edges as an indented tree, one line per SMC."""
    from rich.tree import Tree as RichTree

    from smccli.inspect.tree_text import describe_action, describe_perception
    from smccli.learn.tree import ROOT

    root = RichTree(f"[bold]{ROOT}[/] (root)")
    stack = [(ROOT, root)]
    while stack:
        node, branch = stack.pop()
        added = []
        for e in tree.children(node):
            srcs = escape(", ".join(f"{s.log}@{s.t0:.1f}-{s.t1:.1f}s" for s in e.sources))
            what = describe_perception(e.smc, tree.params.perception)
            child = branch.add(
                f"[cyan]{e.id}[/] -> [bold]{e.child}[/]  {what}  ||  "
                f"{describe_action(e.smc)}  [dim]support {e.support}: {srcs}[/]"
            )
            added.append((e.child, child))
        stack.extend(reversed(added))
    out.print(root)
