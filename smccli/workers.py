"""Worker processes for compile and campaigns: never forked from a process that holds
MuJoCo or GL state (an EGL context does not survive ``fork``).

A fork server that has only imported the given modules (no model, no context) forks them,
which spares each worker the imports (1-3 s: MuJoCo, open3d, scipy) and, after the first
pool, the server's too; spawn where the platform has no fork server. Never the caller's
``__main__``: a script without the ``if __name__ == "__main__":`` guard would run in it.
"""

from __future__ import annotations

import multiprocessing
from multiprocessing.context import BaseContext


def clean_context(preload: list[str]) -> BaseContext:
    """A multiprocessing context whose workers start with ``preload`` (module names)
    imported: ``forkserver`` where there is one, else ``spawn``."""
    methods = multiprocessing.get_all_start_methods()
    ctx = multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")
    if ctx.get_start_method() == "forkserver":
        ctx.set_forkserver_preload(preload)
    return ctx
