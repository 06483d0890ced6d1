"""Teaching during replay (``smc replay TREE --teach script --script FILE``).

A pick_place tree taught only the cube stops at the root on a layout with the pyramid;
with ``--teach script`` the pyramid's script continues from that state, its log names the
tree, the digest and the node, the tree gains the branch at the root with its version + 1,
and a campaign over both variants then succeeds with no teaching.
"""

from __future__ import annotations

import json
import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from conftest import SAMPLE_LOGS, sha256, smc  # noqa: E402

from smccli.execute.campaign import run_campaign  # noqa: E402
from smccli.execute.episode import layout_for  # noqa: E402
from smccli.learn.compile import compile_logs  # noqa: E402
from smccli.learn.tree import ROOT, digest, load_tree  # noqa: E402
from smccli.logs import read_log  # noqa: E402
from smccli.world.scene import load_scene  # noqa: E402

PYRAMID_SCRIPT = SAMPLE_LOGS / "pick_place" / "demo2.yaml"


@pytest.fixture
def cube_tree(tmp_path):
    path = tmp_path / "tree.json"
    compile_logs([SAMPLE_LOGS / "pick_place" / "demo1.mcap"], path)  # the cube only
    return path


@pytest.fixture
def pyramid_layout(tmp_path):
    scene = load_scene("pick_place")
    layout = next(lay for i in range(100) if "grey_pyramid" in (lay := layout_for(scene, 7, i)))
    path = tmp_path / "layout.json"
    path.write_text(json.dumps({k: list(v) for k, v in layout.items()}))
    return path


@pytest.mark.slow
def test_taught_branch_grows_from_the_stop_and_the_tree_then_needs_no_teacher(
    cube_tree, pyramid_layout, tmp_path
) -> None:
    before = load_tree(cube_tree)
    untouched = sha256(cube_tree)
    r = smc("replay", cube_tree, "--layout", pyramid_layout)
    assert r.returncode == 1 and "no_contingent_smc" in r.stdout, r.stdout + r.stderr
    assert sha256(cube_tree) == untouched, "without --teach nothing changes"

    r = smc(
        "replay", cube_tree, "--layout", pyramid_layout, "--teach", "script", "--script",
        PYRAMID_SCRIPT,
    )  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    assert "taught at n0" in r.stdout
    taught = tmp_path / "tree_taught_n0_000.mcap"
    meta = read_log(taught).metadata
    assert meta["teach_node"] == ROOT and meta["teach_tree"] == "tree.json"
    assert meta["teach_tree_digest"] == digest(before)

    after = load_tree(cube_tree)
    assert after.version == before.version + 1
    assert after.history[-1]["logs"] == [
        {"name": taught.name, "sha256": sha256(taught), "fragments": 2, "at": ROOT}
    ]
    roots = after.children(ROOT)
    assert len(roots) == 2 and len(after.edges) == 4
    new = [e for e in after.edges if e.sources[0].log == taught.name]
    assert [e.parent for e in new] == [ROOT, new[0].child] and all(e.support == 1 for e in new)

    # Both variants, no teacher: each trial is deterministic, so every one must succeed.
    summary = run_campaign(cube_tree, trials=16, seed=2, workers=2)
    variants = {k for r in summary["trial_results"] for k in r["layout"]}
    assert {"orange_cube", "grey_pyramid"} <= variants
    assert summary["success_rate"] >= 0.99, summary["failures"]


def test_teach_options_are_checked_before_anything_runs(cube_tree, pyramid_layout) -> None:
    r = smc("replay", cube_tree, "--layout", pyramid_layout, "--teach", "script")
    assert r.returncode == 2 and "--teach script needs --script" in r.stderr
    r = smc("replay", cube_tree, "--trials", "2", "--teach", "script", "--script", PYRAMID_SCRIPT)
    assert r.returncode == 2 and "does not go with --trials" in r.stderr
    r = smc("replay", cube_tree, "--teach", "mouse", "--script", PYRAMID_SCRIPT)
    assert r.returncode == 2 and "expected script or keyboard" in r.stderr
    assert not list(cube_tree.parent.glob("*_taught_*.mcap"))
