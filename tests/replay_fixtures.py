"""Demonstrations recorded from the sample scripts and compiled into trees, built once per
test session (shared by test_replay.py and test_campaign.py through a cache directory)."""

from __future__ import annotations

import os
from pathlib import Path

from smccli.outputs import ExclusiveLock

os.environ.setdefault("MUJOCO_GL", "egl")

REPO = Path(__file__).resolve().parent.parent
SCRIPTS = REPO / "sample_logs"
DEMOS = {
    "bench_pick": ["demo"],
    "pick_place": ["demo1", "demo2"],
    "weigh_sort": ["demo_light", "demo_heavy"],
}


def record_demo(scene: str, name: str, out: Path, seed: int = 0) -> Path:
    """Record ``sample_logs/<scene>/<name>.yaml`` into ``out`` (once)."""
    from smccli.record.session import RecordConfig, record

    if not out.exists():
        record(
            RecordConfig(
                scene=scene, script=SCRIPTS / scene / f"{name}.yaml", output=out, seed=seed
            )
        )
    return out


def build(
    root: Path, scene: str, names: list[str] | None = None, *, tag: str = ""
) -> tuple[list[Path], Path]:
    """Record the scene's demos (or ``names``) under ``root`` and compile them; cached."""
    from smccli.learn.compile import compile_logs

    names = names or DEMOS[scene]
    root.mkdir(parents=True, exist_ok=True)
    lock = ExclusiveLock(root / f"{scene}.lock")
    lock.acquire(timeout=1800)  # another test process may be recording the same demos
    try:
        logs = [record_demo(scene, n, root / f"{scene}_{n}.mcap") for n in names]
        tree = root / f"{scene}{tag}_{'_'.join(names)}.json"
        if not tree.exists():
            compile_logs(logs, tree)
    finally:
        lock.release()
    return logs, tree


def cache_root(tmp_path_factory) -> Path:
    """One directory per session, the same for every test module."""
    return Path(tmp_path_factory.getbasetemp()) / "replay_fixtures"
