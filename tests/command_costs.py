"""Where the suite's ``smc`` commands spend their time: ``SMC_CMDLOG=F make test``, then
``python tests/command_costs.py F``. Totals per subcommand (count, CPU, wall [s]) and the
costliest command lines (docs/testing.md)."""

from __future__ import annotations

import collections
import json
import sys


def main(path: str, top: int = 15) -> None:
    rows = [json.loads(line) for line in open(path)]
    cpu: collections.Counter[str] = collections.Counter()
    wall: collections.Counter[str] = collections.Counter()
    count: collections.Counter[str] = collections.Counter()
    for r in rows:
        argv = r["argv"]
        name = " ".join(argv[:2]) if argv[:2] == ["robots", "import"] else argv[0]
        cpu[name] += r["cpu_s"]
        wall[name] += r["wall_s"]
        count[name] += 1
    print(f"{len(rows)} commands: {sum(cpu.values()):.0f} s CPU, {sum(wall.values()):.0f} s wall")
    for name, seconds in cpu.most_common():
        print(f"  {name:<15} {count[name]:>4}  {seconds:7.1f} s CPU  {wall[name]:7.1f} s wall")
    print("costliest:")
    for r in sorted(rows, key=lambda r: -r["cpu_s"])[:top]:
        print(f"  {r['cpu_s']:6.1f} s CPU {r['wall_s']:6.1f} s wall  {' '.join(r['argv'])[:100]}")


if __name__ == "__main__":
    main(sys.argv[1])
