"""``make sample-logs``: record every teleop script under ``sample_logs/<scene>/`` into
``<script>.mcap`` beside it, with seed 0 and reproducible chunking (same bytes every run)."""

from __future__ import annotations

import sys
from pathlib import Path

from smccli.record.session import RecordConfig, record

ROOT = Path(__file__).resolve().parents[2] / "sample_logs"


def scripts(root: Path = ROOT) -> list[Path]:
    """Teleop scripts of the sample demonstrations, sorted."""
    return sorted(root.glob("*/*.yaml"))


def main() -> int:
    for script in scripts():
        out = script.with_suffix(".mcap")
        summary = record(
            RecordConfig(
                scene=script.parent.name,
                script=script,
                seed=0,
                output=out,
                force=True,
                reproducible=True,
            )
        )
        print(
            f"{out.relative_to(ROOT.parent)}: {summary.duration:.1f} s, "
            f"{summary.fragments} marks, {summary.size_bytes / 1e6:.2f} MB"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
