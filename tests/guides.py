"""The guides in ``docs/`` as tests: the files a guide shows and the commands it runs.

A guide marks each file the reader writes by a fenced block whose first line is a comment
naming its path (``# file: sort/scene.yaml``, ``<!-- file: sort/scene.xml -->``), and its
commands by ``console`` blocks whose lines start with ``$ ``. A test writes exactly those
files into a fresh folder and runs exactly those commands there, in order.
"""

from __future__ import annotations

import re
import shlex
from collections.abc import Callable
from pathlib import Path
from typing import Any

_BLOCK = re.compile(r"^```(\w*)\n(.*?)^```", re.DOTALL | re.MULTILINE)
_FILE = re.compile(r"^(?:#|<!--)\s*file:\s*(\S+?)\s*(?:-->)?$")
_VAR = re.compile(r"\$([A-Z_][A-Z0-9_]*)")


def guide_files(guide: Path) -> dict[str, str]:
    """Path (relative to the reader's folder) -> text, for every file block of ``guide``."""
    files = {}
    for _, body in _BLOCK.findall(guide.read_text(encoding="utf-8")):
        first, _, rest = body.partition("\n")
        m = _FILE.match(first.strip())
        if m:
            assert m.group(1) not in files, f"{guide}: {m.group(1)} shown twice"
            files[m.group(1)] = rest
    return files


def guide_commands(guide: Path, env: dict[str, str] | None = None) -> list[list[str]]:
    """The argument lists of every ``$ `` line of the guide's ``console`` blocks, in order,
    ``$NAME`` replaced by ``env[NAME]`` as the reader's shell would (a variable the guide
    asks the reader to set)."""
    env = env or {}

    def expand(word: str) -> str:
        return _VAR.sub(lambda m: env[m.group(1)], word)

    commands = []
    for lang, body in _BLOCK.findall(guide.read_text(encoding="utf-8")):
        if lang == "console":
            lines = [line[2:] for line in body.splitlines() if line[:2] == "$ "]
            commands += [[expand(w) for w in shlex.split(line)] for line in lines]
    return commands


def write_guide_files(guide: Path, folder: Path) -> dict[str, Path]:
    """Write the guide's files under ``folder``; returns their paths."""
    written = {}
    for rel, text in guide_files(guide).items():
        path = folder / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        written[rel] = path
    return written


SUCCEEDED = re.compile(r"(\d+)/(\d+) succeeded")
"""A campaign's summary line: ``NAME: 39/40 succeeded = ...``."""


def run_guide_as_written(
    guide: Path, folder: Path, smc: Callable[..., Any], env: dict[str, str] | None = None
) -> None:
    """Write the guide's files into ``folder`` and run its commands there with ``smc``
    (``env``: the variables the guide asks the reader to set): each must exit 0 without a
    traceback, and each campaign run at least 40 trials with 95 % succeeding."""
    assert guide_files(guide) and guide_commands(guide, env), f"{guide}: no files or commands"
    write_guide_files(guide, folder)
    campaigns = []
    for argv in guide_commands(guide, env):
        assert argv[0] == "smc", argv
        proc = smc(*argv[1:], cwd=folder, timeout=900)
        assert proc.returncode == 0, (argv, proc.stdout[-2000:], proc.stderr[-2000:])
        assert "Traceback" not in proc.stderr, proc.stderr
        campaigns += list(SUCCEEDED.finditer(proc.stdout + proc.stderr))
    assert campaigns, f"{guide}: no campaign"
    for m in campaigns:
        ok, n = int(m.group(1)), int(m.group(2))
        assert n >= 40 and ok >= 0.95 * n, m.group(0)
