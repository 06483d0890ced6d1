"""Shared fixtures: a seeded RNG, the sample logs, demos re-recorded with other seeds, trees."""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from zygote import Command, Zygote

os.environ.setdefault("MUJOCO_GL", "egl")

REPO = Path(__file__).resolve().parent.parent
# The commands' disk cache (simplified meshes, smccli/world/render_mesh.py): the clone's,
# not the user's home.
os.environ.setdefault("SMC_CACHE_DIR", str(REPO / ".cache" / "smc"))
SAMPLE_LOGS = REPO / "sample_logs"
SCENES = ("pick_place", "weigh_sort", "bench_pick")


SMC_ENV = {**os.environ, "COLUMNS": "250", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
"""The real command's environment: wide tables (rows do not wrap), headless rendering."""


_ZYGOTE = Zygote(SMC_ENV, REPO)


def smc(
    *args: str | Path, timeout: float = 300, cwd: Path = REPO
) -> subprocess.CompletedProcess[str]:
    """Run the real ``smc`` command (``python -m smccli.cli ARGS``) in a process of its own,
    forked from one that has already imported smc (:mod:`zygote`)."""
    return _ZYGOTE.run([str(a) for a in args], Path(cwd), timeout)


def smc_start(
    *args: str | Path,
    out: Path,
    err: Path | None = None,
    env: dict[str, str] | None = None,
    cwd: Path = REPO,
) -> Command:
    """The real ``smc`` command started beside the test (a robot, the node that drives it),
    forked from the zygote with ``env`` (default: the suite's), writing to ``out`` and
    ``err`` (default: ``out`` too): a ``Popen``-like :class:`zygote.Command`."""
    return _ZYGOTE.start([str(a) for a in args], Path(cwd), Path(out), Path(err or out), env)


def smc_process(
    *args: str | Path, timeout: float = 300, cwd: Path = REPO
) -> subprocess.CompletedProcess[str]:
    """``python -m smccli.cli ARGS`` started from nothing (what a user's shell does)."""
    return subprocess.run(
        [sys.executable, "-m", "smccli.cli", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=SMC_ENV,
        cwd=cwd,
    )


def pytest_collection_modifyitems(session, config, items) -> None:
    """Costly test files first (seconds per file in tests/durations.json, `make
    test-durations`; a file not listed counts as the median one): `--dist loadfile` hands
    whole files to the workers in collection order, so the long ones start first and short
    ones fill the end. Tests keep their order within a file."""
    table = REPO / "tests" / "durations.json"
    cost = json.loads(table.read_text()) if table.is_file() else {}
    unknown = float(np.median(list(cost.values()))) if cost else 0.0
    files = [item.nodeid.split("::")[0] for item in items]
    first = {f: i for i, f in reversed(list(enumerate(files)))}
    order = {
        id(item): (-cost.get(f, unknown), first[f]) for item, f in zip(items, files, strict=True)
    }
    items.sort(key=lambda item: order[id(item)])


def pytest_sessionfinish(session, exitstatus) -> None:
    _ZYGOTE.close()


def sha256(path: Path) -> str:
    """Hex SHA-256 of a file's bytes (to show an output was left byte-identical)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(0)


def first_view(scene, layout):
    """The camera frame and the robot's geometry of a fresh Sim of ``scene`` on ``layout``
    (what the robot sees before it moves)."""
    from smccli.world.sim import Sim

    sim = Sim(scene, layout)
    try:
        return sim.render_camera(), sim.robot_geometry()
    finally:
        sim.close()


def sample_log_paths(scene: str) -> list[Path]:
    """The committed sample demonstrations of a scene (made by ``make sample-logs``)."""
    paths = sorted((SAMPLE_LOGS / scene).glob("*.mcap"))
    assert paths, f"no sample logs under {SAMPLE_LOGS / scene}: run `make sample-logs`"
    return paths


@pytest.fixture(scope="session")
def sample_logs() -> dict[str, list[Path]]:
    return {s: sample_log_paths(s) for s in SCENES}


@contextmanager
def built_once(tmp_path_factory, name: str) -> Iterator[tuple[Path, bool]]:
    """``(folder, build)``: a folder shared by every test process of the run (pytest-xdist's
    workers share the run's temporary root) and whether this caller must build its files.
    The first process to take the lock builds, the others wait for it and reuse the files;
    a build that raises leaves the folder to be built again by the next."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent
    folder = root / f"shared-{name}"
    folder.mkdir(exist_ok=True)
    with open(root / f"shared-{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        done = folder / ".built"
        yield folder, not done.exists()
        done.touch()


@pytest.fixture(scope="session")
def sample_trees(tmp_path_factory, sample_logs) -> dict[str, Path]:
    """Each scene's sample demos compiled into a tree (once per run)."""
    from smccli.learn.compile import compile_logs

    with built_once(tmp_path_factory, "trees") as (root, build):
        out = {scene: root / f"{scene}.json" for scene in sample_logs}
        if build:
            for scene, logs in sample_logs.items():
                compile_logs(logs, out[scene])
    return out


TWIN_THRESHOLD = [0.25, 0.35, 0.41]
"""How far a white twin of the white box differs from it per channel, the look-alike
family's calibration (:func:`smccli.bench.lookalike.calibrate`, 95th percentile, to two
decimals): the tests' trials tell look-alikes apart by it without calibrating."""


def _clumsy_tree(tmp_path_factory, operator: int) -> Path:
    """The look-alike family's tree on development seed ``operator``: that clumsy
    operator's demonstration (smccli/bench/learning.py) recorded and compiled (once per
    run)."""
    from smccli.bench.learning import record_demos
    from smccli.learn.compile import compile_logs

    with built_once(tmp_path_factory, f"clumsy-{operator}") as (root, build):
        tree = root / "tree.json"
        if build:
            compile_logs(record_demos(root, 1, first=operator), tree, rebuild=True)
    return tree


@pytest.fixture(scope="session")
def clumsy_tree_0(tmp_path_factory) -> Path:
    """Operator 0's tree (:func:`_clumsy_tree`)."""
    return _clumsy_tree(tmp_path_factory, 0)


@pytest.fixture(scope="session")
def clumsy_tree_2(tmp_path_factory) -> Path:
    """Operator 2's tree (:func:`_clumsy_tree`): it closes the gripper at 94 % of the
    grasp's fragment (the mark comes after the fingers settled)."""
    return _clumsy_tree(tmp_path_factory, 2)


@pytest.fixture(scope="session")
def reseeded_logs(tmp_path_factory) -> dict[int, dict[str, list[Path]]]:
    """The sample scripts recorded again with seed 1 (tremor, hesitation, speed),
    each from its own random layout, as users record them (``--randomize``; once per run)."""
    from smccli.record.session import RecordConfig, record

    out: dict[int, dict[str, list[Path]]] = {}
    with built_once(tmp_path_factory, "reseeded") as (root, build):
        for seed in (1,):
            out[seed] = {}
            for scene in SCENES:
                paths = []
                for k, script in enumerate(sorted((SAMPLE_LOGS / scene).glob("*.yaml"))):
                    path = root / f"{scene}_{script.stem}_s{seed}.mcap"
                    if build:
                        # Another seed per script: the scene's demonstrations start apart too.
                        cfg = RecordConfig(
                            scene=scene,
                            script=script,
                            seed=10 * seed + k,
                            output=path,
                            randomize=True,
                        )
                        record(cfg)
                    paths.append(path)
                out[seed][scene] = paths
    return out


@pytest.fixture(scope="session")
def vendor_models() -> Path:
    """The vendors' model files `make models` unpacks (smccli/world/vendor.py). Missing:
    the test is skipped with the command to run, except in CI (``CI=true``), where it fails."""
    from smccli.world.vendor import VENDOR_DIR, WHEELS

    missing = [w.filename for w in WHEELS if not (VENDOR_DIR / f".{w.filename}.unpacked").is_file()]
    if missing:
        why = (
            f"vendor models not unpacked in {VENDOR_DIR} ({', '.join(missing)}): run `make models`"
        )
        if os.environ.get("CI", "").lower() in ("true", "1"):
            pytest.fail(why)
        pytest.skip(why)
    return VENDOR_DIR
