"""Shared fixtures: a seeded RNG, the sample logs, demos re-recorded with other seeds, trees."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

REPO = Path(__file__).resolve().parent.parent
SAMPLE_LOGS = REPO / "sample_logs"
SCENES = ("pick_place", "weigh_sort", "bench_pick")


SMC_ENV = {**os.environ, "COLUMNS": "250", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
"""The real command's environment: wide tables (rows do not wrap), headless rendering."""


def smc(
    *args: str | Path, timeout: float = 300, cwd: Path = REPO
) -> subprocess.CompletedProcess[str]:
    """Run the real ``smc`` command (``python -m smccli.cli ARGS``) in a subprocess."""
    return subprocess.run(
        [sys.executable, "-m", "smccli.cli", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=SMC_ENV,
        cwd=cwd,
    )


def sha256(path: Path) -> str:
    """Hex SHA-256 of a file's bytes (to show an output was left byte-identical)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(0)


def sample_log_paths(scene: str) -> list[Path]:
    """The committed sample demonstrations of a scene (made by ``make sample-logs``)."""
    paths = sorted((SAMPLE_LOGS / scene).glob("*.mcap"))
    assert paths, f"no sample logs under {SAMPLE_LOGS / scene}: run `make sample-logs`"
    return paths


@pytest.fixture(scope="session")
def sample_logs() -> dict[str, list[Path]]:
    return {s: sample_log_paths(s) for s in SCENES}


@pytest.fixture(scope="session")
def sample_trees(tmp_path_factory, sample_logs) -> dict[str, Path]:
    """Each scene's sample demos compiled into a tree."""
    from smccli.learn.compile import compile_logs

    root = tmp_path_factory.mktemp("trees")
    out = {}
    for scene, logs in sample_logs.items():
        path = root / f"{scene}.json"
        compile_logs(logs, path)
        out[scene] = path
    return out


@pytest.fixture(scope="session")
def reseeded_logs(tmp_path_factory) -> dict[int, dict[str, list[Path]]]:
    """The sample scripts recorded again with seed 1 (tremor, hesitation, speed),
    each from its own random layout, as users record them (``--randomize``)."""
    from smccli.record.session import RecordConfig, record

    root = tmp_path_factory.mktemp("reseeded")
    out: dict[int, dict[str, list[Path]]] = {}
    for seed in (1,):
        out[seed] = {}
        for scene in SCENES:
            paths = []
            for k, script in enumerate(sorted((SAMPLE_LOGS / scene).glob("*.yaml"))):
                path = root / f"{scene}_{script.stem}_s{seed}.mcap"
                # Another seed per script: the scene's demonstrations start apart too.
                cfg = RecordConfig(
                    scene=scene, script=script, seed=10 * seed + k, output=path, randomize=True
                )
                record(cfg)
                paths.append(path)
            out[seed][scene] = paths
    return out
