"""docs/own_task.md ("Teach your own task") built and run exactly as written: a scene of
its own with variants and nested success criteria, two demonstrations, a tree, campaigns.
A file of its own so that a parallel run gives it a worker of its own (the longest guide)."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import REPO, smc
from guides import run_guide_as_written


@pytest.mark.slow
def test_own_task_guide_runs_as_written(tmp_path: Path) -> None:
    run_guide_as_written(REPO / "docs" / "own_task.md", tmp_path, smc)
