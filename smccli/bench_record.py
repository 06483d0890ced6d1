"""Benchmark of ``smc record`` with the script operator: speed against real time, log size.

    python -m smccli.bench_record [--repeats 3]

Prints, per sample script: simulated seconds, wall seconds, real-time factor, log size and
size per demo second. Results go to ``docs/bench_record.json``.
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

from smccli.record import RecordConfig, record
from smccli.sample_logs import scripts

ROOT = Path(__file__).resolve().parent.parent


def run(repeats: int = 3) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for script in scripts():
            best: dict | None = None
            for r in range(repeats):
                out = Path(tmp) / f"{script.stem}_{r}.mcap"
                t0 = time.perf_counter()
                s = record(
                    RecordConfig(scene=script.parent.name, script=script, seed=r, output=out)
                )
                wall = time.perf_counter() - t0
                row: dict[str, object] = {
                    "scene": script.parent.name,
                    "script": script.name,
                    "sim_s": round(s.duration, 2),
                    "wall_s": round(wall, 2),
                    "realtime_factor": round(s.duration / wall, 2),
                    "size_mb": round(s.size_bytes / 1e6, 2),
                    "kb_per_demo_s": round(s.size_bytes / 1e3 / s.duration, 1),
                }
                if best is None or float(row["wall_s"]) < float(best["wall_s"]):  # type: ignore[arg-type]
                    best = row
            assert best is not None
            rows.append(best)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    rows = run(args.repeats)
    print(
        f"{'script':32s} {'sim s':>6s} {'wall s':>7s} {'x real time':>11s} {'MB':>6s} "
        f"{'kB/demo s':>9s}"
    )
    for r in rows:
        print(
            f"{r['scene'] + '/' + r['script']:32s} {r['sim_s']:6.1f} {r['wall_s']:7.2f} "
            f"{r['realtime_factor']:11.1f} {r['size_mb']:6.2f} {r['kb_per_demo_s']:9.1f}"
        )
    doc = {
        "command": "python -m smccli.bench_record",
        "machine": platform.platform(),
        "cpus": __import__("os").cpu_count(),
        "best_of": args.repeats,
        "rows": rows,
    }
    (ROOT / "docs").mkdir(exist_ok=True)
    (ROOT / "docs" / "bench_record.json").write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
