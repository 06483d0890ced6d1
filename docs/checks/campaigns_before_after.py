"""Did a change move a campaign? Run the same campaigns from two checkouts and compare.

Compiles the sample logs of a few scenes with the smccli it imports and runs a campaign of
each (seed 0, 2 workers); writes OUTDIR/cmp.json: per scene, each trial's index, outcome,
path, duration (to 1 µs) and reason. Only public API that has been stable since the
campaigns began, so an older checkout runs it too:

    PYTHONPATH=OLD_CHECKOUT python docs/checks/campaigns_before_after.py /tmp/old
    python docs/checks/campaigns_before_after.py /tmp/new
    cmp /tmp/old/cmp.json /tmp/new/cmp.json
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from smccli.execute.campaign import run_trials
from smccli.execute.episode import resolve
from smccli.learn.compile import compile_logs

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"
CAMPAIGNS = {"pick_place": 40, "bench_pick": 60, "rooms": 40, "weigh_sort": 30}


def main(out_dir: Path) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    results = {}
    for scene, trials in CAMPAIGNS.items():
        tree_path = out_dir / f"{scene}.json"
        if not tree_path.exists():
            compile_logs(sorted((SAMPLES / scene).glob("*.mcap")), tree_path)
        tree, sc = resolve(tree_path, None)
        res = run_trials(tree, sc, trials=trials, seed=0, workers=2)
        results[scene] = [(r.index, r.outcome, r.path, round(r.duration, 6), r.reason) for r in res]
        print(f"{scene}: {sum(r.success for r in res)}/{trials}", flush=True)
    (out_dir / "cmp.json").write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
