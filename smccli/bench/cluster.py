"""Campaign throughput against workers: ``python -m smccli.bench.cluster``.

The sample ``bench_pick`` tree, ``--trials`` (40) trials with the same seed, run by local
processes (``--workers``) and by a Dask ``LocalCluster`` on 127.0.0.1 (``--cluster``) with
1 and 2 workers (this machine's cores). Every run must give the same outcomes: the table
is only worth reading if scale-out changes nothing but the wall time.

Writes ``docs/bench_cluster.json`` (``--out``).
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import argparse  # noqa: E402
import sys  # noqa: E402
from typing import Any  # noqa: E402

from smccli.bench.meta import campaign_line, campaign_row, machine, write_rows  # noqa: E402
from smccli.bench.paper import REPO  # noqa: E402
from smccli.bench.throughput import Agreement, bench_pick_tree, parse_campaign_args  # noqa: E402
from smccli.execute.campaign import run_campaign  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-workers", type=int, default=os.cpu_count() or 1)
    args = parse_campaign_args(ap, argv, 40, REPO / "docs" / "bench_cluster.json")
    meta = machine()
    from distributed import LocalCluster

    with bench_pick_tree() as tree:
        rows: list[dict[str, Any]] = []
        agreement = Agreement()
        for n in range(1, args.max_workers + 1):
            for runner in ("processes", "dask"):
                if runner == "processes":
                    s = run_campaign(tree, trials=args.trials, seed=args.seed, workers=n)
                else:
                    with LocalCluster(
                        n_workers=n,
                        threads_per_worker=1,
                        processes=True,
                        host="127.0.0.1",
                        dashboard_address=None,
                    ) as cluster:
                        s = run_campaign(
                            tree,
                            trials=args.trials,
                            seed=args.seed,
                            cluster=cluster.scheduler_address,
                        )
                if agreement.differs(s):
                    print(f"{runner} x {n}: outcomes differ from the first run", file=sys.stderr)
                    return 1
                rows.append(campaign_row(s, runner=runner, workers=n))
                rate = f"{s['wall_s']:.1f} s, {s['trials_per_second']:.2f} trials/s"
                print(f"{runner:9s} {n} workers: {campaign_line('bench_pick', s)}; {rate}")
    write_rows(args.out, __spec__.name, argv, meta, rows, scene="bench_pick", seed=args.seed)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
