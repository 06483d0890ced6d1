"""Development and held-out seeds of the benchmarks: ``python -m smccli.bench.seeds [NAME]``.

A campaign's trial ``i`` with seed ``S`` runs on the layout drawn from ``[S, i]``. Seeds in
:data:`DEV_SEEDS` are the development range: tests, debugging notes and check scripts use
them, and a figure measured there was looked at trial by trial, its failures replayed and
fixed. A benchmark's held-out seed is drawn from a hash of its name and
:data:`HELD_OUT_VERSION`, a number nobody picked; it is run only to report (``--seed
held-out`` of every ``smccli.bench`` module), never to debug, and ``tests/test_seeds.py``
fails when a test or a check script names one. Once a held-out figure has been debugged on
(a failing trial replayed), raise the version: every benchmark draws a fresh seed.

Without an argument it prints every benchmark's held-out seed; with a name, that one's
(for ``smc replay --seed``).
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

DEV_SEEDS = range(0, 100_000)
"""Seeds for tests and debugging: every seed below 100,000."""
HELD_OUT_VERSION = 1
"""Raise it when a held-out figure was debugged on: every held-out seed changes."""
BENCHMARKS = ("paper", "rooms", "look", "learning", "lookalike", "loco_manip", "ros1")
"""The benchmarks with a held-out seed: the ``smccli.bench`` modules' names, and
``loco_manip`` (the mobile manipulator's campaign, run with ``smc replay``)."""


def held_out_seed(benchmark: str, version: int = HELD_OUT_VERSION) -> int:
    """The held-out seed of ``benchmark``: the first 4 bytes of SHA-256 of
    ``"smc held-out <benchmark> v<version>"``, lifted above :data:`DEV_SEEDS`."""
    digest = hashlib.sha256(f"smc held-out {benchmark} v{version}".encode()).digest()
    return DEV_SEEDS.stop + int.from_bytes(digest[:4], "big") % (2**31 - DEV_SEEDS.stop)


def seed_option(benchmark: str):  # noqa: ANN201 (argparse type)
    """An argparse ``type`` for ``--seed``: an integer, or ``held-out`` for the benchmark's
    held-out seed."""

    def parse(text: str) -> int:
        if text == "held-out":
            return held_out_seed(benchmark)
        try:
            return int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"--seed {text!r}: an integer, or held-out") from None

    parse.__name__ = "seed"
    return parse


def is_held_out(seed: int) -> bool:
    """Whether ``seed`` lies outside the development range (a figure to report, not tune)."""
    return seed not in DEV_SEEDS


def results_dir(seed: int) -> Path:
    """Where a benchmark run on ``seed`` writes by default: ``docs/``, or ``docs/held_out/``
    (made if missing) for a held-out seed; the development figures stay beside them."""
    docs = Path(__file__).resolve().parents[2] / "docs"
    if not is_held_out(seed):
        return docs
    (docs / "held_out" / "img").mkdir(parents=True, exist_ok=True)
    return docs / "held_out"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m smccli.bench.seeds", description=__doc__.split("\n")[0]
    )
    ap.add_argument("benchmark", nargs="?", choices=BENCHMARKS)
    args = ap.parse_args(argv)
    if args.benchmark:
        print(held_out_seed(args.benchmark))
    else:
        for name in BENCHMARKS:
            print(f"{name}: {held_out_seed(name)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
