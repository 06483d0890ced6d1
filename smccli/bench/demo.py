"""``make demo``: the whole pipeline once, on the paper's benchmark task (section 5.1).

Records the bench_pick demonstration with the scripted operator, compiles it into a tree,
replays the tree on a layout it has never seen, and writes a Rerun recording of the tree
and both traces. Everything goes to ``out/demo/``.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "out" / "demo"


def _smc(*args: str) -> None:
    cmd = [sys.executable, "-m", "smccli.cli", *args]
    print("$ smc " + " ".join(args), flush=True)
    proc = subprocess.run(cmd, cwd=ROOT)
    if proc.returncode != 0:
        sys.exit(proc.returncode)


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    demo, tree = OUT / "demo.mcap", OUT / "tree.json"
    replay, report = OUT / "replay.mcap", OUT / "report.json"
    _smc(
        "record",
        "--scene",
        "bench_pick",
        "--operator",
        "script",
        "--script",
        str(ROOT / "sample_logs" / "bench_pick" / "demo.yaml"),
        "--seed",
        "0",
        "-o",
        str(demo),
        "--force",
    )
    _smc("compile", str(demo), "-o", str(tree), "--rebuild")
    _smc("replay", str(tree), "--seed", "7", "-o", str(replay), "--report", str(report), "--force")
    _smc("inspect", str(tree), str(demo), str(replay), "--save", str(OUT / "demo.rrd"), "--force")
    print(f"\ndone: {OUT} (open demo.rrd with `rerun {OUT / 'demo.rrd'}`)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
