"""inspect for a mobile base (scene rooms, paper 4.2): the two committed sample
demonstrations compiled into a tree, one replay of it, and the .rrd read back: lidar scans
in the world, the base's path and pose, room histograms, decisions with their D_P terms,
the stored scans and scan-frame goals, the rooms' outlines."""

from __future__ import annotations

import os
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from rerun.chunk import RrdReader  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402
from test_inspect import read_rrd  # noqa: E402

from smccli.inspect.recording import inspect  # noqa: E402
from smccli.learn.frames import goal_at_scan_pose  # noqa: E402
from smccli.learn.tree import Tree, load_tree  # noqa: E402
from smccli.logs import Log, read_log  # noqa: E402
from smccli.perception.histogram import histogram_size  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
ROOMS = REPO / "sample_logs" / "rooms"
X_RANGE, Y_RANGE = (-1.1, 6.6), (-1.6, 5.6)
"""The rooms' walls, with a margin [m]."""

pytestmark = pytest.mark.skipif(
    not (ROOMS / "demo1.mcap").is_file() or not (ROOMS / "demo2.mcap").is_file(),
    reason="sample_logs/rooms not present",
)


@dataclass(frozen=True)
class Inspected:
    tree: Tree
    demo: Log
    replay: Log
    rrd: dict[str, dict[str, dict]]
    """recording id -> entity path -> {"archetypes", "rows", "columns"}."""
    tree_only: dict[str, dict]
    """The recording of the tree alone."""
    warnings: tuple[str, ...]
    blueprint_views: set[tuple[str, str]]
    """(view class, origin) of the blueprint's views."""


def _views(path: Path) -> set[tuple[str, str]]:
    reader = RrdReader(path)
    views: dict[str, dict[str, str]] = defaultdict(dict)
    for bp in reader.blueprints():
        for chunk in reader.stream(store=bp):
            batch = chunk.to_record_batch()
            for name, key in (
                ("ViewBlueprint:class_identifier", "class"),
                ("ViewBlueprint:space_origin", "origin"),
            ):
                if name in batch.schema.names:
                    for row in batch.column(name).to_pylist():
                        if row:
                            views[chunk.entity_path][key] = row[0]
    return {(v.get("class", ""), v.get("origin", "")) for v in views.values()}


def _rows(entity: dict, column: str) -> list:
    """The rows of a component column (None where a row does not hold it)."""
    return entity["columns"][column]


def _instances(entity: dict, column: str) -> list:
    return [v for row in entity["columns"][column] if row is not None for v in row]


@pytest.fixture(scope="module")
def inspected(tmp_path_factory) -> Inspected:
    from smccli.execute.episode import run_episode
    from smccli.learn.compile import compile_logs

    root = tmp_path_factory.mktemp("rooms")
    tree_path = root / "tree.json"
    compile_logs([ROOMS / "demo1.mcap", ROOMS / "demo2.mcap"], tree_path)
    replay_path = root / "replay.mcap"
    run_episode(tree_path, seed=0, output=replay_path)
    out = root / "rooms.rrd"
    result = inspect(tree_path, [ROOMS / "demo1.mcap", replay_path], save=out)
    assert result.recordings == ("demo1", "replay")
    alone = root / "tree.rrd"
    inspect(tree_path, [], save=alone)
    return Inspected(
        tree=load_tree(tree_path),
        demo=read_log(ROOMS / "demo1.mcap"),
        replay=read_log(replay_path),
        rrd=read_rrd(out),
        tree_only=next(iter(read_rrd(alone).values())),
        warnings=result.warnings,
        blueprint_views=_views(out),
    )


def _inside_rooms(pts: np.ndarray) -> bool:
    return bool(
        np.all((pts[:, 0] >= X_RANGE[0]) & (pts[:, 0] <= X_RANGE[1]))
        and np.all((pts[:, 1] >= Y_RANGE[0]) & (pts[:, 1] <= Y_RANGE[1]))
    )


def test_no_warnings(inspected):
    assert inspected.warnings == ()


@pytest.mark.parametrize("rid", ["demo1", "replay"])
def test_scans_are_points_in_the_world(inspected, rid):
    rec = inspected.rrd[rid]
    log = inspected.demo if rid == "demo1" else inspected.replay
    scan = rec["/world/lidar/scan"]
    assert scan["archetypes"] == {"Points3D"}
    per_scan = [np.asarray(r) for r in _rows(scan, "Points3D:positions") if r is not None]
    # Every scan of a 10 Hz log fits under MAX_SCAN_POINTS: none is thinned out.
    assert len(per_scan) == len(log.scans) > 100
    assert min(len(p) for p in per_scan) >= 300  # hundreds of returns each
    pts = np.concatenate(per_scan)
    assert _inside_rooms(pts), (pts.min(axis=0), pts.max(axis=0))
    assert np.ptp(pts[:, 0]) > 5.0 and np.ptp(pts[:, 1]) > 3.0  # the whole floor, not one spot
    # In one frame: two scans from poses a metre or more apart see the same walls.
    t = np.array([sc.t for sc in log.scans])
    xy = np.column_stack([np.interp(t, log.poi_t, log.poi[:, i]) for i in (0, 1)])
    k = int(np.argmax(np.linalg.norm(xy - xy[0], axis=1) > 1.0))
    assert k > 0
    near, _ = cKDTree(per_scan[0][:, :2]).query(per_scan[k][:, :2])
    assert np.median(near) < 0.05, np.median(near)
    # The lidar's pose at each scan.
    assert rec["/world/lidar/pose"]["rows"] == len(log.scans)


@pytest.mark.parametrize("rid", ["demo1", "replay"])
def test_base_path_and_pose(inspected, rid):
    rec = inspected.rrd[rid]
    log = inspected.demo if rid == "demo1" else inspected.replay
    strips = _instances(rec["/world/poi/path"], "LineStrips3D:strips")
    assert len(strips) == 1
    path = np.asarray(strips[0])
    assert len(path) == len(log.poi_t) > 1000
    assert np.allclose(path[:, 2], 0.0)  # on the floor
    assert np.linalg.norm(path[-1, :2] - log.poi[-1, :2]) < 1e-3
    assert _inside_rooms(path)
    base = rec["/world/base"]
    assert "Boxes3D" in base["archetypes"] and base["rows"] == len(log.poi_t)
    centre = np.asarray(_rows(base, "Boxes3D:centers")[-1][0])
    assert np.linalg.norm(centre[:2] - log.poi[-1, :2]) < 0.1
    heading = rec["/world/base/heading"]
    assert heading["rows"] == len(log.poi_t)
    v = np.asarray(_rows(heading, "Arrows3D:vectors")[-1][0])
    yaw = log.poi[-1, 3]
    assert abs(np.arctan2(v[1], v[0]) - np.arctan2(np.sin(yaw), np.cos(yaw))) < 1e-3


def test_demo_ends_at_its_goal(inspected):
    # Demonstration 1 ends in room 3 at green_goal (1.4, 2.35).
    path = np.asarray(
        _instances(inspected.rrd["demo1"]["/world/poi/path"], "LineStrips3D:strips")[0]
    )
    assert np.linalg.norm(path[-1, :2] - [1.4, 2.35]) < 0.1


@pytest.mark.parametrize("rid", ["demo1", "replay"])
def test_room_histograms(inspected, rid):
    rec = inspected.rrd[rid]
    n_bins = histogram_size(inspected.tree.params.perception)
    cam = rec["/signals/room_histogram/camera"]
    assert cam["archetypes"] == {"BarChart"} and cam["rows"] == 3  # one per decision point
    for values in _rows(cam, "BarChart:values"):
        h = np.asarray(values[0]["buffer"], dtype=float)  # one TensorData per row
        assert h.size == n_bins and abs(h.sum() - 1.0) < 1e-3
    smc = rec["/signals/room_histogram/smc"]
    assert "BarChart" in smc["archetypes"]
    texts = _instances(rec["/events/perception"], "TextLog:text")
    assert len(texts) == 3 and all("room mostly" in t and "d_room" in t for t in texts)
    assert ("BarChart", "/signals/room_histogram") in inspected.blueprint_views


def test_replay_decisions(inspected):
    rec, log = inspected.rrd["replay"], inspected.replay
    assert len(log.decisions) == 3
    texts = _instances(rec["/events/decisions"], "TextLog:text")
    assert len(texts) == 3
    chosen = [d["chosen"] for d in log.decisions]
    assert all(c is not None for c in chosen)
    for d, text in zip(log.decisions, texts, strict=True):
        assert f"chose {d['chosen']}" in text
        for c in d["candidates"]:
            assert "room" in c["terms"] and "scan" in c["terms"]
            assert f"{c['edge']} d_p=" in text and f"room {c['terms']['room']:.3f}" in text
            for term in ("room", "scan"):
                ent = rec[f"/signals/decision/{term}/{c['edge']}"]
                assert ent["archetypes"] == {"Scalars"}
                got = _instances(ent, "Scalars:scalars")
                assert any(abs(g - c["terms"][term]) < 1e-9 for g in got)
    goal = rec["/world/decisions/goal"]
    assert {"Points3D", "Arrows3D"} <= goal["archetypes"] and goal["rows"] == 3
    origins = [np.asarray(r[0]) for r in _rows(goal, "Arrows3D:origins") if r]
    vectors = [np.asarray(r[0]) for r in _rows(goal, "Arrows3D:vectors") if r]
    assert len(origins) == 3
    for d, o, v in zip(log.decisions, origins, vectors, strict=True):
        g = np.asarray(d["mapped_goal"])
        assert np.allclose(o[:2], g[:2], atol=1e-5)
        assert abs(np.arctan2(v[1], v[0]) - np.arctan2(np.sin(g[3]), np.cos(g[3]))) < 1e-3
    assert rec["/world/decisions/lidar"]["rows"] == 3
    assert "LineStrips3D" in rec["/world/decisions/planned"]["archetypes"]


@pytest.mark.parametrize("rid", ["demo1", "replay", None])
def test_tree_scans_goals_and_labels(inspected, rid):
    rec = inspected.tree_only if rid is None else inspected.rrd[rid]
    tree = inspected.tree
    text = dict(
        zip(
            _instances(rec["/tree"], "GraphNodes:node_ids"),
            _instances(rec["/tree"], "GraphNodes:labels"),
            strict=True,
        )
    )
    labels = [text[e.id] for e in tree.edges]
    n_scan = 0
    for e, label in zip(tree.edges, labels, strict=True):
        p, a = e.smc.perception, e.smc.action
        assert p.room is not None and "room mostly" in label and "object" not in label
        if a.goal_frame != "scan":
            continue
        n_scan += 1
        x, y, _ = p.scan_pose
        assert f"scan at ({x:.2f}, {y:.2f})" in label
        scan = np.asarray(_instances(rec[f"/world/actions/{e.id}/scan"], "Points3D:positions"))
        assert len(scan) >= 300 and _inside_rooms(scan)
        goal = rec[f"/world/actions/{e.id}/goal_pose"]
        assert goal["archetypes"] == {"Arrows3D"}
        origin = np.asarray(_instances(goal, "Arrows3D:origins")[0])
        want = goal_at_scan_pose(np.asarray(a.goal)[[0, 1, 3]], np.asarray(p.scan_pose))
        assert np.allclose(origin[:2], want[:2], atol=1e-5)
        # The goal in the world is where the demonstrated path went.
        assert np.linalg.norm(want[:2] - a.dmp.goal[:2]) < 0.1
    assert n_scan == len(tree.edges) == 4
    rooms = rec["/world/rooms"]
    assert rooms["archetypes"] == {"LineStrips3D"}
    assert set(_instances(rooms, "LineStrips3D:labels")) == {"room1", "room2", "room3"}
    assert "Arrows3D" in rec["/world/places"]["archetypes"]
