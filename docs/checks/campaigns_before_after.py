"""Did a change move a campaign? Run the same campaigns from two checkouts and compare.

Compiles the sample logs of a few scenes with the smccli it imports and runs a campaign of
each (seed 0, 2 workers); writes OUTDIR/cmp.json: per scene, the compiled tree's digest
(of its content: the compile time left out) and every trial's repeatable fields
(outcome, path, duration, reason, every candidate's D_P, the mapped goals, the final
poses: all but wall-clock timings) written with repr's 17 significant digits, so a
change in the last bit shows. Only public API that has been stable since the campaigns
began, so an older checkout runs it too:

    PYTHONPATH=OLD_CHECKOUT python docs/checks/campaigns_before_after.py /tmp/old
    python docs/checks/campaigns_before_after.py /tmp/new
    cmp /tmp/old/cmp.json /tmp/new/cmp.json

When they differ, ``python docs/checks/campaigns_before_after.py --diff OLD NEW`` says which
fields moved, in how many trials and by how much at most.
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
        results[scene] = {
            "tree_digest": json.loads(tree_path.read_text())["digest"],
            "trials": [r.repeatable() for r in res],
        }
        print(f"{scene}: {sum(r.success for r in res)}/{trials}", flush=True)
    (out_dir / "cmp.json").write_text(json.dumps(results, indent=1) + "\n")


def _walk(x: object, y: object, path: str, out: dict[str, list[float]]) -> None:
    if isinstance(x, dict) and isinstance(y, dict):
        for k in x:
            _walk(x[k], y.get(k), f"{path}/{k}", out)
    elif isinstance(x, list) and isinstance(y, list) and len(x) == len(y):
        for u, v in zip(x, y, strict=True):
            _walk(u, v, path, out)
    elif isinstance(x, float) and isinstance(y, float):
        if x != y:
            out.setdefault(path, []).append(abs(x - y))
    elif x != y:
        out.setdefault(f"{path} (not a number)", []).append(float("inf"))


def diff(old: Path, new: Path) -> None:
    a, b = json.loads(old.read_text()), json.loads(new.read_text())
    for scene in a:
        ta, tb = a[scene]["trials"], b[scene]["trials"]
        same = sum(
            all(x[k] == y[k] for k in ("outcome", "path", "duration", "reason"))
            for x, y in zip(ta, tb, strict=True)
        )
        tree = "same" if a[scene]["tree_digest"] == b[scene]["tree_digest"] else "differs"
        print(f"{scene}: tree {tree}; outcome, path, duration, reason equal in {same}/{len(ta)}")
        out: dict[str, list[float]] = {}
        for x, y in zip(ta, tb, strict=True):
            _walk(x, y, "", out)
        for field, d in sorted(out.items()):
            print(f"    {field}: {len(d)} values differ, at most {max(d):.3g}")


if __name__ == "__main__":
    if sys.argv[1] == "--diff":
        diff(Path(sys.argv[2]), Path(sys.argv[3]))
    else:
        main(Path(sys.argv[1]))
