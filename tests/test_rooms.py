"""The `rooms` scene end to end (paper 4.2): two demonstrations from different starts merge,
then branch by the arrow's colour; replay reaches the arrow's goal from random starts,
with odometry drift too, and stops with the distances where the tree does not apply."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import SAMPLE_LOGS, smc

from smccli.errors import SceneError, ScriptError
from smccli.execute.episode import episode, layout_for, resolve
from smccli.execute.evaluation import score
from smccli.learn.compile import compile_logs
from smccli.learn.contingency import d_a, d_p, scan_transform
from smccli.learn.frames import goal_at_scan_pose
from smccli.learn.tree import ROOT, load_tree
from smccli.logs import read_log
from smccli.record.operators import load_script, parse_script, run_script, script_layout
from smccli.world.layout import nominal_layout, sample_layout
from smccli.world.scene import ROBOT_KEY, SCENES_DIR, load_scene, load_scene_from_text
from smccli.world.sim import OdometryDrift, Sim
from smccli.world.truth import Truth

DEMOS = sorted((SAMPLE_LOGS / "rooms").glob("demo*.mcap"))


@pytest.fixture(scope="module")
def scene():
    return load_scene("rooms")


@pytest.fixture(scope="module")
def tree_path(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rooms") / "tree.json"
    compile_logs(DEMOS, path)
    return path


# --- the demonstrations ------------------------------------------------------------------


@pytest.mark.parametrize("name", ["demo1", "demo2"])
def test_demo_scripts_reach_their_goal_without_touching_anything(scene, name: str) -> None:
    script = load_script(SAMPLE_LOGS / "rooms" / f"{name}.yaml")
    sim = Sim(scene, script_layout(scene, script))
    touched: set[str] = set()
    marks = []
    for out in run_script(script, sim):
        touched.update(Truth(sim).robot_contacts())
        marks += [m.label for m in out.marks]
    assert marks == ["at_doorway", "read_poster", "done"]
    assert Truth(sim).success(), Truth(sim).success().reason
    assert not touched


def test_sample_logs_are_small_and_carry_the_scans() -> None:
    assert [p.name for p in DEMOS] == ["demo1.mcap", "demo2.mcap"]
    for path in DEMOS:
        assert path.stat().st_size < 5e6, path
        log = read_log(path)
        assert len(log.scans) == len(log.frames) > 100  # the lidar on the camera's 10 Hz
        assert all(len(s.ranges) == 360 for s in log.scans)
        # Different starts: the demonstrations do not begin from one layout.
    starts = [read_log(p).poi[0] for p in DEMOS]
    assert math.dist(starts[0][:2], starts[1][:2]) > 0.5


def test_rerun_mcap_importer_shows_the_scan_as_points() -> None:
    from rerun.chunk import McapReader

    positions = []
    for chunk in McapReader(DEMOS[1], include_topic_regex=["/lidar/points"]).stream():
        batch = chunk.to_record_batch()
        if "Points3D:positions" in batch.schema.names:
            positions += batch.column("Points3D:positions").to_pylist()
    assert len(positions) == len(read_log(DEMOS[1]).scans)
    first = np.array(positions[0])
    assert first.shape == (360, 3)  # every beam of room 1 returns
    assert 0.3 < np.linalg.norm(first[:, :2], axis=1).min() < 8.0


def test_demos_merge_then_branch_by_the_arrow(tree_path: Path) -> None:
    tree = load_tree(tree_path)
    (first,) = tree.children(ROOT)
    (second,) = tree.children(first.child)
    branches = tree.children(second.child)
    assert first.support == second.support == 2
    assert sorted(e.support for e in branches) == [1, 1] and len(tree.edges) == 4
    for e in tree.edges:
        p = e.smc.perception
        assert e.smc.action.goal_frame == "scan"
        assert p.room is not None and p.scan is not None and p.cluster is None
    # The two branches: the same place (scan), another arrow (room colours), far-apart goals.
    a, b = (e.smc for e in branches)
    T = scan_transform(a.perception, b.perception, tree.params)
    assert T is not None
    assert d_p(a.perception, b.perception, tree.params, T) > tree.params.t_hp
    assert d_a(a.action, b.action, tree.params, T) > 1.0
    goals = {
        e.sources[0].log: goal_at_scan_pose(
            e.smc.action.goal[[0, 1, 3]], e.smc.perception.scan_pose
        )
        for e in branches
    }
    scene = load_scene("rooms")
    assert goals["demo1.mcap"] == pytest.approx(scene.place("green_goal"), abs=0.02)
    assert goals["demo2.mcap"] == pytest.approx(scene.place("yellow_goal"), abs=0.02)


# --- replay -------------------------------------------------------------------------------


@pytest.mark.slow
def test_small_campaign_reaches_the_arrows_goal(tree_path: Path, tmp_path: Path) -> None:
    report = tmp_path / "campaign.json"
    proc = smc("replay", tree_path, "--trials", "16", "--workers", "2", "--report", report)
    assert proc.returncode == 0, proc.stderr
    import json

    summary = json.loads(report.read_text())
    assert summary["successes"] == 16, summary["failures"]
    starts = [r["layout"][ROBOT_KEY] for r in summary["trial_results"]]
    assert max(math.hypot(x, y) for x, y, _, _ in starts) > 0.4  # random starts in room 1
    assert max(abs(yaw) for *_, yaw in starts) > 0.5
    arrows = {next(k for k in r["layout"] if k != ROBOT_KEY) for r in summary["trial_results"]}
    assert arrows == {"green_arrow_poster", "yellow_arrow_poster"}
    assert "ICP" in proc.stdout and summary["latency_ms"]["icp_p50"] > 0


def test_odometry_drift_is_cancelled_by_the_scans(tree_path: Path, scene) -> None:
    tree, _ = resolve(tree_path, None)
    for trial in range(4):
        off = []

        def drifted(sim: Sim, off: list[float] = off) -> None:  # after control: odometry's error
            odom, truth = sim.poi(), Truth(sim).base_pose()
            off.append(math.dist(odom[:2], truth[:2]))

        layout = layout_for(scene, seed=0, trial=trial)
        r = episode(tree, scene, layout, drift=OdometryDrift(0.03, 0.03), evaluate=drifted)
        assert r.success, r.reason
        assert off[0] > 0.25  # odometry alone would have missed by far more than 10 cm


def test_no_poster_means_no_contingent_smc_with_the_distances(tree_path: Path, scene) -> None:
    tree, _ = resolve(tree_path, None)
    layout = {ROBOT_KEY: (0.2, -0.1, 0.0, 0.3)}  # no arrow on the wall
    r = episode(tree, scene, layout)
    assert r.outcome == "no_contingent_smc" and len(r.path) == 2, r.reason
    last = r.decisions[-1]
    assert last.chosen is None and len(last.candidates) == 2
    assert all(c.d_p > tree.params.t_hp for c in last.candidates)
    assert "e3 d_p=" in r.reason and "e4 d_p=" in r.reason


def test_a_room_the_tree_never_saw_stops_at_the_root(tree_path: Path, scene) -> None:
    tree, _ = resolve(tree_path, None)
    layout = {"green_arrow_poster": scene.object("green_arrow_poster").pose}
    layout[ROBOT_KEY] = (0.0, 2.5, 0.0, 0.0)  # in room 3
    r = episode(tree, scene, layout)
    assert r.outcome == "no_contingent_smc" and not r.path, r.reason
    (cand,) = r.decisions[0].candidates
    assert dict(cand.terms)["scan"] > tree.params.t_hp  # the scan alone tells


def test_failure_causes_of_a_base(scene) -> None:
    sim = Sim(scene, {"green_arrow_poster": (6.44, 0.75, 1.0, math.pi), ROBOT_KEY: (1.0, 0, 0, 0)})
    v = score(sim, scene, {}, outcome="success", reason="leaf", actions=())
    assert v.outcome == "wrong_room"  # green: the goal is in room 3, the base in room 1
    sim.reset({"green_arrow_poster": (6.44, 0.75, 1.0, math.pi), ROBOT_KEY: (1.0, 2.6, 0, 3.1)})
    v = score(sim, scene, {}, outcome="success", reason="leaf", actions=())
    assert v.outcome == "goal_missed" and "green_goal" in v.reason
    sim.reset({"green_arrow_poster": (6.44, 0.75, 1.0, math.pi), ROBOT_KEY: (1.4, 2.35, 0, 3.1)})
    assert score(sim, scene, {}, outcome="success", reason="leaf", actions=()).success
    v = score(
        sim, scene, {}, outcome="success", reason="leaf", actions=(), collisions=["room1_desk"]
    )
    assert v.outcome == "collision" and "room1_desk" in v.reason
    # The yellow arrow's criterion does not count where the green arrow is shown.
    sim.reset({"yellow_arrow_poster": (6.44, 0.75, 1.0, math.pi), ROBOT_KEY: (1.4, 2.35, 0, 3.1)})
    assert score(sim, scene, {}, outcome="success", reason="leaf", actions=()).outcome == (
        "wrong_room"
    )


def test_contacts_name_what_the_base_hit(scene) -> None:
    sim = Sim(scene, {ROBOT_KEY: (2.2, -0.3, 0.0, 0.0)})
    from smccli.world.sensors import PoiCommand

    for _ in range(200):  # push into the desk south of it
        sim.step(PoiCommand(sim.t, np.array([2.2, -1.2, 0.0, 0.0]), 1.0))
    assert "room1_desk" in Truth(sim).robot_contacts()


# --- scene and script files ----------------------------------------------------------------


def _scene_text(old: str, new: str) -> str:
    text = (SCENES_DIR / "rooms" / "scene.yaml").read_text()
    assert old in text
    return text.replace(old, new, 1)


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("{robot_at: green_goal}", "{robot_at: kitchen}", "no place 'kitchen' (places: doorway"),
        ("variant: green_arrow\n", "variant: blue_arrow\n", "no variant 'blue_arrow'"),
        ("yaw: [-0.7854, 0.7854]", "yaw: [0.7854, -0.7854]", "start.range.yaw (line"),
        ("- name: green_arrow_poster", "- name: robot", "'robot' is reserved"),
        ("room2: [[3.0, 6.5, -1.5, 3.0]]", "room2: [[6.5, 3.0, -1.5, 3.0]]", "regions.room2[0]"),
    ],
)
def test_scene_file_problems_are_one_line(old: str, new: str, message: str) -> None:
    built = load_scene("rooms")
    with pytest.raises(SceneError) as err:
        load_scene_from_text(_scene_text(old, new), built.mjcf, built.robot.yaml_text)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_start_pose_needs_a_base() -> None:
    text = (SCENES_DIR / "bench_pick" / "scene.yaml").read_text() + "start: {pose: [0, 0, 0]}\n"
    xml = load_scene("bench_pick").mjcf
    with pytest.raises(SceneError, match=r"start \(line \d+\): a start pose is for a mobile base"):
        load_scene_from_text(text, xml)


def test_script_to_an_unknown_place_is_one_line(scene) -> None:
    script = parse_script("scene: rooms\nsteps:\n  - go_to: kitchen\n", "x.yaml")
    with pytest.raises(
        ScriptError, match=r"x.yaml: step 0 \(line 3, move_to\): no place 'kitchen'"
    ):
        list(run_script(script, Sim(scene)))


def _rooms_with_start(tmp_path, x: list[float], y: list[float], name: str):
    """The rooms scene with another start range (a user's scene file)."""
    text = (SCENES_DIR / "rooms" / "scene.yaml").read_text()
    text = text.replace("mjcf: scene.xml", f"mjcf: {SCENES_DIR / 'rooms' / 'scene.xml'}")
    text = text.replace(
        "range: {x: [-0.5, 0.5], y: [-0.5, 0.5], yaw: [-0.7854, 0.7854]}",
        f"range: {{x: {x}, y: {y}, yaw: [-3.14, 3.14]}}",
    )
    assert f"x: {x}" in text
    path = tmp_path / name / "scene.yaml"
    path.parent.mkdir()
    path.write_text(text)
    return path


def test_starts_inside_a_wall_are_drawn_again(tmp_path):
    """A start range over room 1's walls (x -1.2..3.2 m, y -1.7..1.7 m; walls at x = -1, 3
    and y = +-1.5): about a third of the starts drawn from it put the base in a wall. Each
    layout's start is free: the simulator placed there touches nothing."""
    from smccli.world.layout import start_collisions

    path = _rooms_with_start(tmp_path, [-1.2, 3.2], [-1.7, 1.7], "wide")
    scene = load_scene(path)
    raw = np.random.default_rng(0)
    drawn = [
        (raw.uniform(-1.2, 3.2), raw.uniform(-1.7, 1.7), raw.uniform(-3.14, 3.14))
        for _ in range(60)
    ]
    layout = nominal_layout(scene, "green_arrow")
    hits = [start_collisions(scene, {**layout, "robot": (x, y, 0.0, a)}) for x, y, a in drawn]
    assert sum(bool(h) for h in hits) >= 10, "the range reaches into the walls"
    sim = Sim(scene)
    for i in range(40):
        lay = sample_layout(scene, np.random.default_rng([0, i]))
        sim.reset(lay)
        assert Truth(sim).robot_contacts() == [], (lay["robot"], Truth(sim).robot_contacts())


def test_a_start_range_inside_a_wall_is_refused_in_one_line(tmp_path, tree_path):
    """A start range within the wall between rooms 1 and 2: no free start exists; the scene
    is refused with one line naming the file and what to change, exit 2."""
    path = _rooms_with_start(tmp_path, [2.96, 2.99], [-1.0, -0.5], "in_wall")
    with pytest.raises(SceneError, match="start.range leaves the robot no room"):
        sample_layout(load_scene(path), np.random.default_rng(0), max_tries=50)
    for extra in ([], ["--trials", "3", "--workers", "2"]):
        proc = smc("replay", tree_path, "--scene", path, *extra)
        lines = proc.stderr.splitlines()
        assert proc.returncode == 2 and len(lines) == 1, proc.stderr
        assert lines[0].startswith(f"error: {path}: start.range leaves the robot no room")
        assert "room1_wall_e_s" in lines[0]
