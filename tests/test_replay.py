"""Replay (Algorithm 2) on the real MuJoCo scenes: episodes, the replay log, stops, errors,
and the honesty rule (control never reads object state or the ground-truth topic)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from conftest import smc  # noqa: E402
from replay_fixtures import REPO, build, cache_root  # noqa: E402

from smccli.execute.episode import (  # noqa: E402
    EpisodeResult,
    episode,
    layout_for,
    resolve,
    run_episode,
)
from smccli.execute.matching import EdgeStack, equivalent, match_edges  # noqa: E402
from smccli.learn.contingency import ranked  # noqa: E402
from smccli.logs import read_log, strip_topic  # noqa: E402
from smccli.world.sim import Sim  # noqa: E402
from smccli.world.truth import Truth  # noqa: E402

PY = str(REPO / ".venv" / "bin" / "python")


@pytest.fixture(scope="session")
def bench(tmp_path_factory) -> tuple[list[Path], Path]:
    return build(cache_root(tmp_path_factory), "bench_pick")


@pytest.fixture(scope="session")
def pick_demo1(tmp_path_factory) -> tuple[list[Path], Path]:
    return build(cache_root(tmp_path_factory), "pick_place", ["demo1"])


def cli(*args: str, cwd: Path = REPO) -> subprocess.CompletedProcess:
    return smc("replay", *args, cwd=cwd)


def decisions_of(result: EpisodeResult) -> list[tuple]:
    return [
        (
            d.nodes,
            d.chosen,
            [round(c.d_p, 9) for c in d.candidates],
            None if d.mapped_goal is None else np.round(d.mapped_goal, 9).tolist(),
        )
        for d in result.decisions
    ]


def test_episode_on_a_new_layout_succeeds_and_logs_decisions(bench, tmp_path):
    _, tree = bench
    out, report = tmp_path / "replay.mcap", tmp_path / "report.json"
    result = run_episode(tree, seed=7, output=out, report=report)
    assert result.outcome == "success", result.reason
    assert result.success and result.path == ("e1", "e2")
    log = read_log(out)
    assert [d["chosen"] for d in log.decisions] == ["e1", "e2"]
    first = log.decisions[0]
    assert first["node"] == "n0" and first["candidates"][0]["contingent"] is True
    assert len(first["mapped_goal"]) == 4 and first["timings"]["perceive"] > 0
    assert len(log.point_clouds) == 2 and all(len(p.points) > 100 for p in log.point_clouds)
    assert len(log.frames) > 10 and len(log.commands) > 300  # the recorder's topics
    doc = json.loads(report.read_text())
    assert doc["outcome"] == "success" and doc["success"] is True
    assert len(doc["latency_ms"]["per_decision"]) == 2
    assert doc["demo_duration_s"] == pytest.approx(result.demo_duration) and doc["duration_s"] > 0
    # The mapped grasp goal sits on the white box where it really is (evaluation only).
    box = layout_for(resolve(tree, None)[1], 7)["white_box"]
    assert np.hypot(*(np.array(first["mapped_goal"][:2]) - box[:2])) < 0.01


def _match_one(stored, clusters, weight, params) -> tuple[float, int | None]:
    """C_Now of a context against one stored SMC written out from its definition (eq. 36,
    39): the cluster D_P of each seen cluster (:func:`d_cluster`), the first in
    :func:`ranked` order, plus the scale's term."""
    import math

    from smccli.perception import d_cluster

    d, index = 0.0, None
    if stored.cluster is not None:
        pp = params.perception
        ds = np.array([d_cluster(c, stored.cluster, pp) for c in clusters])
        unmeasured = np.array(
            [
                pp.brightness_scale > 0
                and math.isnan(c.brightness)
                and not math.isnan(stored.cluster.brightness)
                for c in clusters
            ]
        )
        index = int(np.argmin(ranked(ds, unmeasured, params.t_hp)))
        d = float(ds[index])
    if stored.weight is not None:
        d += abs(weight - stored.weight) / params.weight_scale
    return d, index


def test_vectorised_match_equals_the_per_edge_definition(tmp_path_factory, bench):
    from smccli.perception import clusters_from_frame

    _, tree_path = build(cache_root(tmp_path_factory), "pick_place")
    for path in (tree_path, bench[1]):
        tree, scene = resolve(path, None)
        sim = Sim(scene, layout_for(scene, 3))
        frame = sim.render_camera()
        clusters = clusters_from_frame(frame, sim.robot_geometry(), tree.params.perception)
        sim.close()
        for weight in (None, 0.0, 0.3):
            edges = [e for e in tree.edges if (e.smc.perception.weight is None) == (weight is None)]
            stack = EdgeStack.build(edges)
            d, idx = match_edges(stack, clusters, weight, tree.params)
            for i, e in enumerate(edges):
                d_ref, index = _match_one(e.smc.perception, clusters, weight, tree.params)
                assert d[i] == pytest.approx(d_ref, abs=1e-9)
                assert (None if idx[i] < 0 else idx[i]) == index


def test_no_contingent_smc_lists_distances_and_exits_1(pick_demo1, tmp_path):
    _, tree = pick_demo1  # one branch: the orange cube onto the green cylinder
    layout = tmp_path / "no_cube.yaml"
    # The cube is off the table (out of the camera's crop); the pyramid looks different.
    layout.write_text("orange_cube: [0.2, -1.6, 0.025, 0.0]\n")
    result = run_episode(tree, layout=layout)
    assert result.outcome == "no_contingent_smc" and not result.success
    (dec,) = result.decisions
    assert dec.chosen is None and dec.candidates and not dec.candidates[0].contingent
    assert "e1 d_p=" in result.reason
    proc = cli(str(tree), "--layout", str(layout))
    assert proc.returncode == 1, proc.stderr
    assert "no_contingent_smc" in proc.stdout and "d_p=" in proc.stdout
    assert "Traceback" not in proc.stderr


def test_bad_tree_files_give_one_line_and_exit_2(bench, tmp_path):
    _, tree = bench
    corrupt = tmp_path / "corrupt.json"
    corrupt.write_text('{"format": "smc-tree", "schema_')
    other_version = tmp_path / "v99.json"
    doc = json.loads(Path(tree).read_text())
    other_version.write_text(json.dumps({**doc, "schema_version": 99}))
    cases = [
        (str(tmp_path / "missing.json"), []),
        (str(corrupt), []),
        (str(other_version), []),
        (str(tree), ["--scene", "bench_pick_panda"]),  # taught on the arm
    ]
    for path, extra in cases:
        proc = cli(path, *extra)
        lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
        assert proc.returncode == 2, (path, proc.stderr)
        assert len(lines) == 1 and "error" in lines[0], proc.stderr
        assert "Traceback" not in proc.stderr


def test_control_never_reads_object_state(bench, monkeypatch):
    _, tree_path = bench
    tree, scene = resolve(tree_path, None)
    layout = layout_for(scene, 11)
    reference = episode(tree, scene, layout)

    def forbidden(*_a, **_k):
        raise AssertionError("object state read during control")

    for name in ("ground_truth", "object_pose", "object_speed", "holds", "success"):
        monkeypatch.setattr(Truth, name, forbidden)
    honest = episode(tree, scene, layout, evaluate=lambda sim: monkeypatch.undo())
    assert honest.outcome == reference.outcome == "success"
    assert decisions_of(honest) == decisions_of(reference)


def test_same_decisions_without_the_ground_truth_topic(bench, tmp_path):
    from smccli.learn.compile import compile_logs

    (log,), tree_path = bench
    stripped = strip_topic(log, tmp_path / "stripped.mcap", "/sim/ground_truth")
    assert "/sim/ground_truth" not in read_log(stripped).topic_counts
    tree2 = tmp_path / "tree2.json"
    compile_logs([stripped], tree2)
    tree, scene = resolve(tree_path, None)
    other, _ = resolve(tree2, None)
    layout = layout_for(scene, 5)
    a = episode(tree, scene, layout)
    b = episode(other, scene, layout)
    assert a.outcome == b.outcome == "success"
    assert decisions_of(a) == decisions_of(b)


def test_frontier_keeps_branches_that_differ_only_by_their_path(bench):
    import dataclasses

    from smccli.learn.tree import insert_chain

    _, tree_path = bench
    tree, scene = resolve(tree_path, None)
    edges = tree.edges
    # The same demonstration with another path (forcing weights x 4) that comes to the goal
    # from the side instead of from above (approach's x and z swapped): another way of
    # doing it, so Algorithm 1 hangs it as a second branch from the root.
    chain = [
        dataclasses.replace(
            e.smc,
            action=dataclasses.replace(
                e.smc.action,
                dmp=dataclasses.replace(e.smc.action.dmp, weights=4 * e.smc.action.dmp.weights),
                approach=e.smc.action.approach[:, [2, 1, 0]],
            ),
        )
        for e in edges
    ]
    forked = insert_chain(tree, chain, [e.sources[0] for e in edges])
    assert len(forked.children("n0")) == 2
    a, b = forked.children("n0")
    assert equivalent(a, b, forked.params)
    result = episode(forked, scene, layout_for(scene, 2))
    assert result.outcome == "success", result.reason
    assert len(result.decisions[1].nodes) == 2  # both branches' decision points
    assert len(result.decisions[1].candidates) == 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(pytest.main([__file__, "-q"]))


def test_the_hand_backs_out_after_the_last_release(bench) -> None:
    """After the tree's last action opened the gripper, the arm lifts its hand RETREAT
    along the approach axis (up): no finger stays on the object it released."""
    from smccli.execute.executor import RETREAT, TreeExecutor
    from smccli.execute.sensing import Sensors

    _, tree_path = bench
    tree, scene = resolve(tree_path, None)
    sim = Sim(scene, layout_for(scene, seed=0))
    commands = []
    executor = TreeExecutor(tree, Sensors(sim, on_step=commands.append))
    outcome, _, _, actions, _ = executor.run()
    poi_end = sim.poi()
    sim.close()
    assert outcome == "success" and actions[-1].event == "open", outcome
    released = [c for c in commands if c.t < actions[-1].t1 - 1e-9][-1].target
    assert commands[-1].target[2] == pytest.approx(released[2] + RETREAT, abs=1e-9)
    np.testing.assert_allclose(commands[-1].target[[0, 1, 3]], released[[0, 1, 3]])
    assert poi_end[2] > released[2] + RETREAT - 0.005  # the POI arrived there
