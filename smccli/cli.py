"""The ``smc`` command line: parse options, show progress, map SmcError to exit codes.

Every command calls one library function; nothing here knows how the work is done.
"""

from __future__ import annotations

import os
import sys
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from smccli.errors import SmcError

if TYPE_CHECKING:
    from smccli.execute.episode import EpisodeResult
    from smccli.execute.teach import TeachConfig
    from smccli.learn.tree import Tree as LearnedTree
    from smccli.world.scene import Scene

os.environ.setdefault("MUJOCO_GL", "egl")

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Teach a robot a task from a few demonstrations (Sensory-Motor "
    "Contingencies, Stefanini et al. 2024).",
)
out = Console(soft_wrap=True)  # a line is never cut: paths stay whole in logs and pipes
err = Console(stderr=True)


def _one_line(text: str) -> str:
    """``text`` on one line, escaped for rich: its whitespace runs (newlines too) collapsed."""
    return escape(" ".join(str(text).split()))


def say(text: str) -> None:
    """A line on stderr, never wrapped: off a terminal (CI, pipes, log files) rich would
    wrap it at 80 columns, cutting file paths in two."""
    err.print(_one_line(text), highlight=False, soft_wrap=True)


def warn(text: str) -> None:
    """``warning: ...`` on one line of stderr."""
    err.print(f"[yellow]warning:[/] {_one_line(text)}", highlight=False, soft_wrap=True)


def _live(*columns, **kwargs) -> Progress:
    """A transient progress display on stderr, only on a terminal: off one, it would leave
    a blank line behind (and logs get plain status lines instead)."""
    return Progress(*columns, console=err, transient=True, disable=not err.is_terminal, **kwargs)


class OperatorKind(str, Enum):
    script = "script"
    keyboard = "keyboard"


class SegmentChoice(str, Enum):
    markers = "markers"
    auto = "auto"
    both = "both"


TopicsOption = Annotated[
    Path | None,
    typer.Option(
        help="The logs are ROS 2 bags: read them through this topic map "
        "(schemas/topic_map.schema.json).",
        dir_okay=False,
    ),
]
"""``--topics MAP``, shared by compile, doctor and inspect."""


@app.command()
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


@app.command()
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


@app.command()
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
) -> None:
    """Record a demonstration (or a session of them) into MCAP logs."""
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
    with _live(
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
    from smccli.world.scene import load_scene

    recorded_in = load_scene(scene)
    for summary in summaries:
        _print_summary(summary, recorded_in)
    summary = summaries[-1]
    if summary.interrupted:
        say(
            f"interrupted ({summary.interrupted}): kept {summary.path} with "
            f"{summary.duration:.1f} s, marked interrupted in its metadata"
        )
        raise typer.Exit(130)


def _band_cell(band: dict | None) -> str:
    """``trials, rate`` of one object's distance band."""
    if band is None or not band["trials"]:
        return "0"
    return f"{band['trials']}, {100 * band['success_rate']:.0f}"


def _print_summary(summary, scene: Scene) -> None:
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
    elif task.get("success") is False:
        warn(f"{summary.path}: the demonstration failed its task ({task.get('reason')})")
    if summary.interrupted is None:  # what compile will say about it, said now
        from smccli.learn.compile import demonstration_warnings

        for warning in demonstration_warnings(summary.path, scene):
            warn(warning)


@app.command("compile")
def compile_cmd(
    logs: Annotated[list[Path], typer.Argument(help="Demonstration logs (.mcap).")],
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
            "per log; 1: none). The tree is the same.",
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

    with _live(
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


def _print_episode(result: EpisodeResult) -> None:
    """Outcome, one row per decision (frontier, choice, D_P of each candidate, goal,
    latency), then the task and wall times."""
    colour = "green" if result.success else "red"
    if result.note:
        out.print(f"note: {escape(result.note)}", highlight=False)
    out.print(f"[bold {colour}]{result.outcome}[/]: {escape(result.reason)}", highlight=False)
    table = Table("node", "chosen", "candidates (d_p, * = contingent)", "goal", "latency [ms]")
    for d in result.decisions:
        cands = ", ".join(
            f"{c.edge} {c.d_p:.3f}{'*' if c.contingent else ''}" for c in d.candidates
        )
        goal = (
            ""
            if d.mapped_goal is None
            else "[" + ", ".join(f"{v:.3f}" for v in d.mapped_goal) + "]"
        )
        table.add_row("/".join(d.nodes), d.chosen or "-", cands, goal, f"{1e3 * d.latency_s:.1f}")
    out.print(table)
    # A path the tree did not take to a leaf (stopped, or taught) has no demonstrated time.
    demo = (
        f"demonstration {result.demo_duration:.2f} s, x{result.duration / result.demo_duration:.2f}"
        if result.demo_duration
        else "no demonstrated path to compare"
    )
    out.print(
        f"task {result.duration:.2f} s ({demo}); wall {result.wall_time:.2f} s"
        + (f"; log {result.output}" if result.output else "")
    )
    if result.taught is not None:
        tt = result.taught
        out.print(
            f"taught at {tt.node}: {escape(str(tt.log))} ({tt.marks} marks) compiled into the "
            f"tree, now version {tt.version}; execution went on from {tt.end}",
            highlight=False,
        )


def _print_campaign(summary: dict[str, Any]) -> None:
    """Success rate with its interval, success by distance band, failures, latency, duration."""
    lo, hi = summary["ci95"]
    if summary.get("note"):
        out.print(f"note: {escape(summary['note'])}", highlight=False)
    out.print(
        f"[bold]{summary['scene']}[/]: {summary['successes']}/{summary['trials']} "
        f"succeeded = {100 * summary['success_rate']:.1f} % "
        f"(95 % CI {100 * lo:.1f}-{100 * hi:.1f} %)",
        highlight=False,
    )
    by_object = summary.get("by_object") or {}
    if len(by_object) > 1:  # each object's distance from where it was demonstrated
        names = sorted(by_object)
        cells = {n: {b["label"]: b for b in by_object[n]} for n in names}
        labels = list(dict.fromkeys(b["label"] for n in names for b in by_object[n]))
        table = Table("distance from demo", *(f"{n}: trials, success [%]" for n in names))
        for label in labels:
            table.add_row(label, *(_band_cell(cells[n].get(label)) for n in names))
    else:
        table = Table("distance from demo", "trials", "success [%]", "95 % CI")
        for b in summary["by_band"]:
            rate = "-" if b["success_rate"] is None else f"{100 * b['success_rate']:.1f}"
            ci = f"{100 * b['ci95'][0]:.0f}-{100 * b['ci95'][1]:.0f}"
            table.add_row(b["label"], str(b["trials"]), rate, ci)
    out.print(table)
    fails = ", ".join(f"{k} {v}" for k, v in summary["failures"].items() if v) or "none"
    out.print(f"failures: {fails}")
    lat, dur = summary["latency_ms"], summary["duration_s"]
    if lat["p50"] is not None:
        icp = f", of which ICP p50 {lat['icp_p50']:.1f} ms" if lat.get("icp_p50") else ""
        out.print(
            f"decision latency p50 {lat['p50']:.1f} ms, p95 {lat['p95']:.1f} ms "
            f"(match p50 {lat['match_p50']:.3f} ms{icp})"
        )
    if dur["p50"] is not None:
        out.print(
            f"task duration p50 {dur['p50']:.2f} s (demonstration {dur['demo']:.2f} s,"
            f" ratio p50 {dur['ratio_p50']:.2f}); {summary['trials_per_second']:.2f} "
            "trials/s"
        )
    if summary.get("cluster"):
        out.print(f"ran on the Dask cluster at {summary['cluster']}: {summary['workers']} workers")


def _print_verification(v: Any) -> None:
    """The divergence of a re-simulated log over time and its verdict; exit 1 when the POI
    or a finger strayed beyond its tolerance."""
    from smccli.execute.verify import FINGER_TOLERANCE, POI_TOLERANCE

    table = Table("t [s]", "POI error [mm]", "finger error [mm]", "other joints [mrad]")
    n = len(v.t)
    for i in sorted({int(k * (n - 1) / 10) for k in range(11)} if n else set()):
        table.add_row(
            f"{v.t[i]:.2f}",
            f"{1e3 * v.poi_error[i]:.4f}",
            f"{1e3 * v.finger_error[i]:.4f}",
            f"{1e3 * v.joint_error[i]:.4f}",
        )
    out.print(table)
    verdict = "[red]diverges[/]" if v.divergent else "[green]reproduces what it recorded[/]"
    first = (
        "" if v.first_divergence is None else f"; first beyond at t = {v.first_divergence:.2f} s"
    )
    out.print(
        f"{escape(str(v.log))} ({v.scene}, {n} commands): {verdict}: POI within "
        f"{1e3 * v.max_poi_error:.4f} mm (tolerance {1e3 * POI_TOLERANCE:.0f}), fingers within "
        f"{1e3 * v.max_finger_error:.4f} mm (tolerance {1e3 * FINGER_TOLERANCE:.0f}); other "
        f"joints within {1e3 * v.max_joint_error:.4f} mrad (not judged){first}",
        highlight=False,
    )
    if v.divergent:
        raise typer.Exit(1)


@app.command()
def verify(
    log: Annotated[Path, typer.Argument(help="A recorded log (.mcap).", dir_okay=False)],
) -> None:
    """Play a log's commands again from its first state: does it mean what it recorded?
    Exit 1 when the POI or a finger strays beyond its tolerance."""
    from smccli.execute.verify import verify_log

    _print_verification(verify_log(log))


@app.command()
def replay(
    tree: Annotated[
        Path | None, typer.Argument(help="Tree file (tree.json); none with --verify.")
    ] = None,
    scene: Annotated[
        str | None, typer.Option(help="Scene name or path; default: the tree's.")
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the layout (and of a campaign).")] = 0,
    layout: Annotated[
        Path | None,
        typer.Option(help="Layout file (YAML/JSON: object -> [x, y, z, yaw]).", dir_okay=False),
    ] = None,
    output: Annotated[
        Path | None, typer.Option("-o", "--output", help="Replay log (.mcap).")
    ] = None,
    report: Annotated[Path | None, typer.Option(help="Report (JSON).")] = None,
    trials: Annotated[int, typer.Option(help="Run a campaign of N randomised layouts.")] = 0,
    workers: Annotated[
        int, typer.Option(help="Processes for a campaign (default: all cores).")
    ] = 0,
    cluster: Annotated[
        str | None,
        typer.Option(
            help="Run the campaign's trials on the workers of this Dask scheduler "
            "(e.g. tcp://10.0.0.5:8786) instead of local processes."
        ),
    ] = None,
    min_success: Annotated[
        float | None, typer.Option(help="Exit 1 if the campaign's success rate is below this.")
    ] = None,
    teach: Annotated[
        str | None,
        typer.Option(
            help="Where no SMC is contingent, an operator (script or keyboard) continues from "
            "there; the continuation is recorded, compiled into the tree from that node, and "
            "execution goes on."
        ),
    ] = None,
    script: Annotated[
        Path | None,
        typer.Option(help="Teleop script of the continuation (--teach script).", dir_okay=False),
    ] = None,
    verify: Annotated[
        Path | None,
        typer.Option(
            help="The same as `smc verify LOG` (kept as an alias): play a recorded log's "
            "commands again and report how far the robot strays (exit 1 beyond tolerance).",
            dir_okay=False,
        ),
    ] = None,
    force: Annotated[bool, typer.Option(help="Overwrite existing outputs.")] = False,
    odometry_drift: Annotated[
        float,
        typer.Option(
            help="A mobile base's odometry error: distance off by this fraction and heading "
            "off by this many rad per metre driven (e.g. 0.02).",
            min=0.0,
            max=0.5,
        ),
    ] = 0.0,
    speed: Annotated[
        float,
        typer.Option(
            help="Play every movement primitive this many times faster than demonstrated "
            "(up to the tree's limit: the robot's POI is held to 0.5 m/s)."
        ),
    ] = 1.0,
    look_period: Annotated[
        float | None,
        typer.Option(
            help="While an arm acts on an object, look at it again every this many seconds "
            "and move the goal where it went (0: never; default 1).",
        ),
    ] = None,
) -> None:
    """Execute the tree autonomously in simulation: one episode or a campaign."""
    from smccli.execute import run_episode
    from smccli.execute.executor import LOOK_PERIOD
    from smccli.execute.verify import verify_log
    from smccli.world.sim import OdometryDrift

    look = LOOK_PERIOD if look_period is None else look_period

    if verify is not None:
        if tree is not None or trials > 0:
            raise SmcError("--verify LOG replays a recording's commands: give no tree or --trials")
        _print_verification(verify_log(verify))
        raise typer.Exit(0)
    if tree is None:
        raise SmcError("replay needs a tree file (or --verify LOG)")
    if teach is not None and trials > 0:
        raise SmcError("--teach continues one episode; it does not go with --trials")
    if script is not None and teach is None:
        raise SmcError("--script is the continuation of --teach script")
    if cluster is not None and trials <= 0:
        raise SmcError("--cluster runs a campaign's trials: give --trials N")
    if cluster is not None and workers:
        raise SmcError("--workers counts local processes; with --cluster the cluster's run")
    drift = OdometryDrift(odometry_drift, odometry_drift) if odometry_drift > 0 else None
    if trials > 0:
        summary = _campaign_with_progress(
            tree,
            trials,
            scene=scene,
            seed=seed,
            workers=workers or (os.cpu_count() or 1),
            report=report,
            force=force,
            drift=drift,
            cluster=cluster,
            speed=speed,
            look_period=look,
        )
        _print_campaign(summary)
        if min_success is not None and summary["success_rate"] < min_success:
            say(f"success rate {summary['success_rate']:.3f} below --min-success {min_success}")
            raise typer.Exit(1)
        return
    result = run_episode(
        tree,
        scene=scene,
        seed=seed,
        layout=layout,
        output=output,
        report=report,
        force=force,
        drift=drift,
        teach=None if teach is None else _teach_config(tree, teach, script),
        speed=speed,
        look_period=look,
    )
    _print_episode(result)
    if result.outcome != "success":
        raise typer.Exit(1)


def _campaign_with_progress(tree: Path, trials: int, **options: Any) -> dict[str, Any]:
    """:func:`~smccli.execute.run_campaign` with a progress bar on a terminal."""
    from smccli.execute import run_campaign

    with _live(
        TextColumn("[bold]campaign[/]"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.description}"),
        TimeElapsedColumn(),
    ) as progress:
        task = progress.add_task("", total=trials)

        def on_trial(done: int, successes: int) -> None:
            progress.update(task, completed=done, description=f"{successes}/{done} succeeded")

        return run_campaign(tree, trials=trials, on_trial=on_trial, **options)


def _teach_config(tree: Path, operator: str, script: Path | None) -> TeachConfig:
    """Teaching where no SMC is contingent (``replay --teach``): the operator's messages
    and a plain line per simulated second on stderr (the viewer's HUD shows it too)."""
    from smccli.execute.teach import TeachConfig

    next_line = [1.0]

    def teach_status(s: Any) -> None:
        if s.t >= next_line[0]:
            say(f"teaching: sim {s.t:6.2f} s  marks {s.marks}")
            next_line[0] = s.t + 1.0

    return TeachConfig(
        tree_path=tree, operator=operator, script=script, on_message=say, on_status=teach_status
    )


@app.command()
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


@app.command()
def doctor(
    logs: Annotated[
        list[Path], typer.Argument(help="Logs to check (.mcap, or a killed recorder's .part).")
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


@app.command()
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


def main() -> None:
    """Entry point: run the app; expected failures become one line and an exit code."""
    try:
        app()
    except SmcError as exc:
        # One line, whatever the message holds: scripts and CI grep for it.
        err.print(f"[bold red]error:[/] {_one_line(str(exc))}", highlight=False, soft_wrap=True)
        sys.exit(exc.exit_code)
    except KeyboardInterrupt:
        say("interrupted")
        sys.exit(130)


if __name__ == "__main__":
    main()
