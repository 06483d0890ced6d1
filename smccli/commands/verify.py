"""``smc verify``: play a log's commands again and show how far the robot strays."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape
from rich.table import Table

from smccli.commands.console import out


def print_verification(v: Any) -> None:
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


def verify(
    log: Annotated[Path, typer.Argument(help="A recorded log (.mcap).", dir_okay=False)],
) -> None:
    """Play a log's commands again from its first state: does it mean what it recorded?
    Exit 1 when the POI or a finger strays beyond its tolerance."""
    from smccli.execute.verify import verify_log

    print_verification(verify_log(log))
