"""What every benchmark file records beside its figures: the machine, the commit, the time.

A figure means little without where and at which commit it was measured.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]


def _git(*args: str) -> str:
    return subprocess.run(
        ["git", *args], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.strip()


def commit() -> str:
    """The checkout's commit (``+dirty`` with uncommitted changes), or ``unknown``."""
    try:
        rev = _git("rev-parse", "--short=12", "HEAD")
        dirty = _git("status", "--porcelain", "--untracked-files=no")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return rev + ("+dirty" if dirty else "")


def machine() -> dict[str, Any]:
    """CPUs, platform, Python, GL backend, commit and start time of this run."""
    return {
        "cpus": os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "gl": os.environ.get("MUJOCO_GL"),
        "commit": commit(),
        "started": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }


def write_rows(
    out: Path,
    module: str,
    argv: list[str] | None,
    meta: dict[str, Any],
    rows: list[dict[str, Any]],
    **fields: Any,
) -> None:
    """Write a benchmark's table of ``rows`` to ``out`` (atomically) with the machine
    ``meta`` (taken when the run started), the command that reruns it and ``fields``."""
    from smccli.outputs import write_atomic

    args = sys.argv[1:] if argv is None else argv
    result = {"machine": meta, "command": " ".join(["python -m", module, *args]), **fields}
    write_atomic(out, json.dumps({**result, "rows": rows}, indent=1) + "\n")


def campaign_row(summary: dict[str, Any], **fields: Any) -> dict[str, Any]:
    """A benchmark table's row for a campaign ``summary`` (:func:`~smccli.execute.run_campaign`):
    ``fields`` first, then its trials, successes, wall time and throughput."""
    keys = ("trials", "successes", "wall_s", "trials_per_second")
    return {**fields, **{k: summary[k] for k in keys}}


def campaign_line(name: str, summary: dict[str, Any]) -> str:
    """One line for a campaign ``summary``: successes, rate, 95 % interval, failures."""
    s = summary
    ci = f" (95 % CI {100 * s['ci95'][0]:.1f}-{100 * s['ci95'][1]:.1f})" if "ci95" in s else ""
    failures = {k: v for k, v in s["failures"].items() if v}
    return (
        f"{name}: {s['successes']}/{s['trials']} = {100 * s['success_rate']:.1f} %{ci}, "
        f"failures {failures}"
    )
