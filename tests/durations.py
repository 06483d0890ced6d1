"""Seconds per test file, from pytest's ``--durations=0`` report on stdin, written to
tests/durations.json (``make test-durations``). conftest.py starts the costly files first."""

from __future__ import annotations

import collections
import json
import re
import sys
from pathlib import Path

OUT = Path(__file__).with_name("durations.json")


def main() -> None:
    cost: collections.Counter[str] = collections.Counter()
    for line in sys.stdin:
        m = re.match(r"\s*([\d.]+)s (?:call|setup|teardown)\s+(\S+?)::", line)
        if m:
            cost[m.group(2)] += float(m.group(1))
    if not cost:
        sys.exit("durations.py: no `--durations=0` lines on stdin")
    part = OUT.with_suffix(".json.part")
    part.write_text(json.dumps({f: round(s) for f, s in cost.most_common()}, indent=1) + "\n")
    part.replace(OUT)


if __name__ == "__main__":
    main()
