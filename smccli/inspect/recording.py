"""``smc inspect``: a tree and its logs as Rerun recordings (docs/design.md section 6).

One recording per log (a tree alone: one recording), all in application ``smc``; each
holds the tree (static, :mod:`.tree_view`) and the log on the timeline ``time``
(simulation seconds, :mod:`.log_view`); a mobile base adds its layers (:mod:`.mobile`).
This module is the entry point, :func:`inspect`, and writes ``--save``'s .rrd; the viewers
``--spawn`` and ``--serve`` run are in :mod:`.serve`, the recordings' ids and blueprint in
:mod:`.plan`, colours and labels in :mod:`.labels`.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from smccli.errors import SmcError
from smccli.inspect.plan import APP_ID, blueprint_for, fill, recording_plan
from smccli.inspect.serve import rerun_binary, serve_recordings, spawn_viewer
from smccli.learn.tree import Tree, load_tree
from smccli.logs.ros2_bag import TopicMap
from smccli.outputs import check_output

if TYPE_CHECKING:
    from smccli.logs.log import Log


@dataclass(frozen=True, slots=True)
class InspectResult:
    """What ``inspect`` produced."""

    recordings: tuple[str, ...]
    """Recording ids, one per log (``tree`` when no log was given)."""
    rrd: Path | None
    """The .rrd written (``--save``), else None."""
    url: str | None = None
    """The web viewer's address (``--serve``), else None."""
    warnings: tuple[str, ...] = field(default_factory=tuple)
    """One-line warnings (log without joint states, unknown edge in a decision...)."""


def inspect(
    tree_path: Path,
    logs: Sequence[Path] = (),
    *,
    save: Path | None = None,
    spawn: bool = False,
    serve: bool = False,
    port: int = 9090,
    grpc_port: int | None = None,
    force: bool = False,
    on_warning: Callable[[str], None] | None = None,
    on_message: Callable[[str], None] | None = None,
    topic_map: TopicMap | None = None,
) -> InspectResult:
    """Show ``tree_path`` and ``logs`` in Rerun: write ``save`` (.rrd), spawn or serve a viewer.
    With ``topic_map`` the logs are ROS 2 bags read through it.

    The output is checked first (its folder exists and is writable; an existing file needs
    ``force``), then inputs are all read and checked: a missing or corrupt tree or log raises
    TreeError / LogError (one line naming the file) before anything is written.
    ``serve`` blocks until Ctrl-C, then stops the viewer it started (see :func:`serve_recordings`);
    ``on_message`` hears the addresses it serves at.
    """
    if sum([save is not None, spawn, serve]) != 1:
        raise SmcError("inspect: choose exactly one of --save, --spawn, --serve")
    warnings: list[str] = []

    def warn(msg: str) -> None:
        warnings.append(msg)
        if on_warning is not None:
            on_warning(msg)

    if save is not None:
        check_output(save, force=force)
    tree = load_tree(Path(tree_path))
    from smccli.logs import read_log
    from smccli.logs.ros2_bag import read_ros2_bag

    loaded = [
        read_log(Path(p), on_warning=warn)
        if topic_map is None
        else read_ros2_bag(Path(p), topic_map, on_warning=warn)
        for p in logs
    ]
    for log in loaded:
        _warn_missing_topics(log, warn)
    if serve:
        addresses = serve_recordings(
            tree,
            loaded,
            port=port,
            grpc_port=grpc_port,
            tree_name=Path(tree_path).name,
            warn=warn,
            on_message=on_message,
        )
        ids = [rid for rid, _ in recording_plan(tree, loaded, Path(tree_path).name)]
        return InspectResult(tuple(ids), None, addresses.viewer, tuple(warnings))
    if spawn:
        ids = spawn_viewer(tree, loaded, tree_name=Path(tree_path).name, warn=warn)
        return InspectResult(tuple(ids), None, None, tuple(warnings))
    assert save is not None
    ids = write_rrd(tree, loaded, Path(save), tree_name=Path(tree_path).name, warn=warn)
    return InspectResult(tuple(ids), Path(save), None, tuple(warnings))


def _warn_missing_topics(log: Log, warn: Callable[[str], None]) -> None:
    """A viewer shows what a log holds: a topic compile would need and the log lacks is a
    warning naming it, not an error (``smc compile`` and ``smc doctor`` refuse such a log)."""
    from smccli.learn.compile import required_topics

    missing = sorted(t for t in required_topics(log) if log.topic_counts.get(t, 0) == 0)
    if missing:
        warn(f"{log.path}: no {', '.join(missing)}: shown without (compile would refuse it)")


def write_rrd(
    tree: Tree,
    logs: Sequence[Log],
    out: Path,
    *,
    tree_name: str = "tree.json",
    warn: Callable[[str], None] = lambda m: None,
) -> list[str]:
    """Write one .rrd holding a recording per log (the tree in each); returns their ids."""
    import rerun as rr

    out = check_output(out, force=True)  # overwriting was the caller's decision
    plan = recording_plan(tree, logs, tree_name)
    bp = blueprint_for(tree, logs)
    with tempfile.TemporaryDirectory(prefix="smc-rrd-", dir=out.parent) as tmp:
        parts = []
        for k, (rid, log) in enumerate(plan):
            part = Path(tmp) / f"{k}.rrd"
            rec = rr.RecordingStream(APP_ID, recording_id=rid)
            rec.save(part, default_blueprint=bp)
            rec.send_recording_name(rid)
            fill(rec, tree, log, warn)
            rec.flush()
            rec.disconnect()
            parts.append(part)
        staged = Path(tmp) / "out.rrd"
        if len(parts) == 1:
            shutil.move(parts[0], staged)
        else:
            # A Python stream writes one recording per file (files with footers cannot be
            # concatenated); the rerun binary merges them and keeps the recordings apart.
            proc = subprocess.run(
                [rerun_binary(), "rrd", "merge", *map(str, parts), "-o", str(staged)],
                capture_output=True,
                text=True,
            )
            if proc.returncode != 0 or not staged.is_file():
                last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
                raise SmcError(f"{out}: rerun rrd merge failed ({last})")
        os.replace(staged, out)
    return [rid for rid, _ in plan]
