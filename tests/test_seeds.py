"""Held-out seeds (smccli/bench/seeds.py): outside the development range, one per benchmark,
and named by no test, check script or debugging note: a figure debugged on is not held out."""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO

from smccli.bench.seeds import (
    BENCHMARKS,
    DEV_SEEDS,
    HELD_OUT_VERSION,
    held_out_seed,
    is_held_out,
    results_dir,
    seed_option,
)


def test_each_benchmark_has_its_own_held_out_seed_outside_the_development_range() -> None:
    seeds = [held_out_seed(b) for b in BENCHMARKS]
    assert len(set(seeds)) == len(seeds)
    assert all(is_held_out(s) and s not in DEV_SEEDS and s < 2**31 for s in seeds)
    # a new version draws new seeds for every benchmark
    assert not set(seeds) & {held_out_seed(b, HELD_OUT_VERSION + 1) for b in BENCHMARKS}
    assert results_dir(seeds[0]).name == "held_out" and results_dir(0).name == "docs"


def test_seed_option_takes_an_integer_or_held_out() -> None:
    parse = seed_option("rooms")
    assert parse("7") == 7
    assert parse("held-out") == held_out_seed("rooms")
    with pytest.raises(argparse.ArgumentTypeError, match="--seed 'seven'"):
        parse("seven")
    out = subprocess.run(
        [sys.executable, "-m", "smccli.bench.seeds", "loco_manip"],
        capture_output=True,
        text=True,
        check=True,
        cwd=REPO,
    ).stdout
    assert out.strip() == str(held_out_seed("loco_manip"))


def _debugging_files() -> list[Path]:
    """What tests and debugging use: the tests, the check scripts, the notes of choices."""
    here = Path(__file__).resolve()
    files = [p for p in (REPO / "tests").rglob("*") if p.is_file() and p != here]
    files += [p for p in (REPO / "docs" / "checks").rglob("*") if p.is_file()]
    files += [REPO / "docs" / "choices.md", REPO / "docs" / "history.md"]
    return [p for p in files if p.suffix in {".py", ".md", ".yaml", ".json", ".sh", ""}]


def test_no_test_or_debugging_note_uses_a_held_out_seed() -> None:
    held_out = {
        str(held_out_seed(b, v)) for b in BENCHMARKS for v in range(1, HELD_OUT_VERSION + 1)
    }
    found = []
    for path in _debugging_files():
        text = path.read_text(errors="replace")
        numbers = set(re.findall(r"\d{6,}", text))
        if numbers & held_out or re.search(r"seed[ =]+held-out|held_out_seed\(", text):
            found.append(str(path.relative_to(REPO)))
    assert not found, f"held-out seeds used in {found}"
