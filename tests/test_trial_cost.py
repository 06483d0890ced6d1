"""The trial-cost probe (:mod:`smccli.bench.trial_probe`) times every stage it names in the
checkout it runs in, without changing what a trial does."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO

from smccli.bench import trial_probe


def test_the_probe_times_each_stage_and_leaves_the_outcomes_alone(sample_trees) -> None:
    tree = sample_trees["bench_pick"]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run(
        [sys.executable, trial_probe.__file__, str(tree), "bench_pick", "2", "3"],
        capture_output=True,
        text=True,
        env=env,
        cwd=REPO,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    probe = json.loads(proc.stdout)
    assert probe["missing"] == []
    spent, calls = probe["spent_s"], probe["calls"]
    assert calls["trial"] == 2 and calls["physics"] == calls["sim_step"] > 100
    # Nested stages fit inside what holds them (control periods run in actions and
    # outside them: holding still at a decision, backing the hand out at the end).
    assert 0 < spent["physics"] < spent["sim_step"] < spent["trial"]
    assert 0 < spent["action"] < spent["trial"]
    assert spent["render:action"] + spent["render:decision"] == pytest.approx(spent["render"])
    assert calls["decide"] == len(probe["latency_ms"])
    # Each call's time is kept by who asked: a decision renders one frame.
    per_call = probe["per_call_ms"]
    assert len(per_call["render:decision"]) == calls["decide"]
    assert sum(per_call["render:decision"]) == pytest.approx(1e3 * spent["render:decision"])
    from smccli.execute.campaign import run_trials
    from smccli.execute.episode import resolve

    t, sc = resolve(Path(tree), "bench_pick")
    plain = [[r.index, r.outcome, r.path, r.reason] for r in run_trials(t, sc, trials=2, seed=3)]
    assert probe["outcomes"] == plain
