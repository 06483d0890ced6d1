"""Campaign throughput on bench_pick: ``python -m smccli.bench.throughput``.

The sample ``bench_pick`` tree, ``--trials`` (200) trials with ``--seed`` (0), run with each
of ``--workers`` (1 2) local processes, as ``smc replay TREE --trials 200 --workers W --seed
0`` does. Per worker count: wall time and trials/s (the campaign's own, without imports or
compiling the tree, but with starting the workers), trials/s per worker, the CPU time the
campaign used (this process and its workers) with trials per CPU second, and the median
trial's wall time inside its worker (a running worker's pace: the rate per core). On a
machine shared with other jobs the wall time says as much about them as about smc, the
CPU time much less. Every run must give the same outcomes (``workers`` changes nothing but
the wall time), else exit 1.

Writes ``docs/bench_throughput.json`` (``--out``).
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import argparse  # noqa: E402
import resource  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
from collections.abc import Iterator  # noqa: E402
from contextlib import contextmanager  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

from smccli.bench.meta import campaign_row, machine, write_rows  # noqa: E402
from smccli.bench.paper import REPO  # noqa: E402
from smccli.execute.campaign import run_campaign  # noqa: E402
from smccli.learn.compile import compile_logs  # noqa: E402
from smccli.outputs import check_output  # noqa: E402


def _cpu_s() -> float:
    """CPU time [s] (user + system) of this process and of its children waited for."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


@contextmanager
def bench_pick_tree() -> Iterator[Path]:
    """The tree of the bench_pick sample logs, compiled into a temporary folder."""
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "bench_pick.json"
        compile_logs(sorted((REPO / "sample_logs" / "bench_pick").glob("*.mcap")), tree)
        yield tree


def parse_campaign_args(
    ap: argparse.ArgumentParser, argv: list[str] | None, trials: int, out: Path
) -> argparse.Namespace:
    """``ap`` with the options of every bench_pick campaign benchmark (``--trials``,
    ``--seed``, ``--out``) parsed from ``argv``; the output file checked."""
    ap.add_argument("--trials", type=int, default=trials)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=out)
    args = ap.parse_args(argv)
    check_output(args.out, force=True)
    return args


class Agreement:
    """Runs of one campaign with other workers must give the same trials: each run's
    (trial index, outcome) pairs against the first run's."""

    def __init__(self) -> None:
        self.first: list[tuple[int, str]] | None = None

    def differs(self, summary: dict[str, Any]) -> bool:
        """Whether ``summary``'s trials differ from the first run's (the first: never)."""
        got = [(r["index"], r["outcome"]) for r in summary["trial_results"]]
        self.first = self.first or got
        return got != self.first


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = parse_campaign_args(ap, argv, 200, REPO / "docs" / "bench_throughput.json")
    meta = machine()
    with bench_pick_tree() as tree:
        rows: list[dict[str, Any]] = []
        agreement = Agreement()
        for n in args.workers:
            load = os.getloadavg()[0]
            cpu0 = _cpu_s()
            s = run_campaign(tree, trials=args.trials, seed=args.seed, workers=n)
            cpu = _cpu_s() - cpu0
            trial_s = float(statistics.median(r["wall_time"] for r in s["trial_results"]))
            if agreement.differs(s):
                print(f"{n} workers: outcomes differ from the first run", file=sys.stderr)
                return 1
            rows.append(
                campaign_row(s, workers=n)
                | {
                    "trials_per_second_per_worker": s["trials_per_second"] / n,
                    "cpu_s": cpu,
                    "trials_per_cpu_second": args.trials / cpu,
                    "trial_wall_s_p50": trial_s,
                    "trials_per_second_per_core_running": 1.0 / trial_s,
                    "load_average_before": load,
                }
            )
            print(
                f"{n} workers: {s['successes']}/{args.trials}, {s['wall_s']:.1f} s wall, "
                f"{s['trials_per_second']:.2f} trials/s ({s['trials_per_second'] / n:.2f} per "
                f"worker), {cpu:.1f} s CPU ({args.trials / cpu:.2f} trials per CPU s), "
                f"median trial {trial_s:.3f} s ({1 / trial_s:.2f} trials/s per core running), "
                f"load before {load:.1f}",
                flush=True,
            )
    write_rows(args.out, __spec__.name, argv, meta, rows, scene="bench_pick", seed=args.seed)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
