"""``smc replay``: run the tree in simulation, one episode or a campaign, and show how it
went."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn
from rich.table import Table

from smccli.commands.console import live, out, say
from smccli.commands.verify import print_verification

if TYPE_CHECKING:
    from smccli.execute.episode import EpisodeResult
    from smccli.execute.teach import TeachConfig


# The options of smc replay, one alias each (the command's signature stays a list).
TreeArg = Annotated[Path | None, typer.Argument(help="Tree file (tree.json); none with --verify.")]
SceneOption = Annotated[str | None, typer.Option(help="Scene name or path; default: the tree's.")]
SeedOption = Annotated[int, typer.Option(help="Seed of the layout (and of a campaign).")]
LayoutOption = Annotated[
    Path | None,
    typer.Option(help="Layout file (YAML/JSON: object -> [x, y, z, yaw]).", dir_okay=False),
]
OutputOption = Annotated[Path | None, typer.Option("-o", "--output", help="Replay log (.mcap).")]
ReportOption = Annotated[Path | None, typer.Option(help="Report (JSON).")]
TrialsOption = Annotated[int, typer.Option(help="Run a campaign of N randomised layouts.")]
WorkersOption = Annotated[int, typer.Option(help="Processes for a campaign (default: all cores).")]
ClusterOption = Annotated[
    str | None,
    typer.Option(
        help="Run the campaign's trials on the workers of this Dask scheduler "
        "(e.g. tcp://10.0.0.5:8786) instead of local processes."
    ),
]
MinSuccessOption = Annotated[
    float | None, typer.Option(help="Exit 1 if the campaign's success rate is below this.")
]
TeachOption = Annotated[
    str | None,
    typer.Option(
        help="Where no SMC is contingent, an operator (script or keyboard) continues from "
        "there; the continuation is recorded, compiled into the tree from that node, and "
        "execution goes on."
    ),
]
ScriptOption = Annotated[
    Path | None,
    typer.Option(help="Teleop script of the continuation (--teach script).", dir_okay=False),
]
VerifyOption = Annotated[
    Path | None,
    typer.Option(
        help="The same as `smc verify LOG` (kept as an alias): play a recorded log's "
        "commands again and report how far the robot strays (exit 1 beyond tolerance).",
        dir_okay=False,
    ),
]
ForceOption = Annotated[bool, typer.Option(help="Overwrite existing outputs.")]
DriftOption = Annotated[
    float,
    typer.Option(
        help="A mobile base's odometry error: distance off by this fraction and heading "
        "off by this many rad per metre driven (e.g. 0.02).",
        min=0.0,
        max=0.5,
    ),
]
SpeedOption = Annotated[
    float,
    typer.Option(
        help="Play every movement primitive this many times faster than demonstrated "
        "(up to the tree's limit: the robot's POI is held to 0.5 m/s)."
    ),
]
LookPeriodOption = Annotated[
    float | None,
    typer.Option(
        help="While an arm acts on an object, look at it again every this many seconds "
        "and move the goal where it went (0: never; default 1).",
    ),
]


def replay(
    tree: TreeArg = None,
    scene: SceneOption = None,
    seed: SeedOption = 0,
    layout: LayoutOption = None,
    output: OutputOption = None,
    report: ReportOption = None,
    trials: TrialsOption = 0,
    workers: WorkersOption = 0,
    cluster: ClusterOption = None,
    min_success: MinSuccessOption = None,
    teach: TeachOption = None,
    script: ScriptOption = None,
    verify: VerifyOption = None,
    force: ForceOption = False,
    odometry_drift: DriftOption = 0.0,
    speed: SpeedOption = 1.0,
    look_period: LookPeriodOption = None,
) -> None:
    """Execute the tree autonomously in simulation: one episode or a campaign."""
    from smccli.execute import replay_command, run_episode
    from smccli.execute.executor import LOOK_PERIOD
    from smccli.execute.verify import verify_log

    look = LOOK_PERIOD if look_period is None else look_period
    kind = replay_command.replay_kind(
        tree=tree,
        trials=trials,
        workers=workers,
        cluster=cluster,
        teach=teach,
        script=script,
        verify=verify,
    )
    if kind == "verify":
        assert verify is not None
        print_verification(verify_log(verify))
        raise typer.Exit(0)
    assert tree is not None
    drift = replay_command.odometry_drift(odometry_drift)
    if kind == "campaign":
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

    with live(
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


def _band_cell(band: dict | None) -> str:
    """``trials, rate`` of one object's distance band."""
    if band is None or not band["trials"]:
        return "0"
    return f"{band['trials']}, {100 * band['success_rate']:.0f}"
