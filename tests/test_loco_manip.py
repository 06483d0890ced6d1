"""loco_manip (paper 5.3): a mobile manipulator opens a sliding door, opens a wardrobe, takes
a green can or a screwdriver and puts it on table C or table D.

The two demonstration scripts succeed in simulation; their sample logs carry both POIs and
compile into the tree of 5.3 (merged up to the grasp of the object, then one branch per
object); replays succeed on randomised layouts (start, wardrobe, object), and when the
wardrobe moves while the robot works.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import mujoco
import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from smccli.execute.campaign import run_campaign, run_trials  # noqa: E402
from smccli.execute.episode import layout_for, resolve, run_episode  # noqa: E402
from smccli.execute.executor import TreeExecutor  # noqa: E402
from smccli.execute.policy import TreePolicy  # noqa: E402
from smccli.execute.sensing import Sensors  # noqa: E402
from smccli.learn.compile import compile_logs  # noqa: E402
from smccli.learn.tree import ROOT, load_tree  # noqa: E402
from smccli.logs import read_log  # noqa: E402
from smccli.perception.colours import colour_name, dominant_rgb  # noqa: E402
from smccli.record.operators import load_script, run_script, script_layout  # noqa: E402
from smccli.world.layout import sample_layout  # noqa: E402
from smccli.world.scene import builtin_names, load_scene  # noqa: E402
from smccli.world.sim import Sim  # noqa: E402
from smccli.world.truth import Truth  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
SAMPLES = REPO / "sample_logs" / "loco_manip"
SCRIPTS = {"can": SAMPLES / "demo_can.yaml", "screwdriver": SAMPLES / "demo_screwdriver.yaml"}


@pytest.fixture(scope="module")
def scene():
    return load_scene("loco_manip")


@pytest.fixture(scope="module")
def tree(tmp_path_factory):
    out = tmp_path_factory.mktemp("loco") / "tree.json"
    compile_logs(sorted(SAMPLES.glob("*.mcap")), out)
    return out


def test_listed_with_its_robot(scene):
    assert "loco_manip" in builtin_names()
    robot = scene.robot
    assert robot.name == "mobile_panda" and robot.base is not None and robot.arm_joints
    assert {s.type for s in robot.sensors} == {"lidar", "camera"}


@pytest.mark.parametrize("variant", ["can", "screwdriver"])
def test_demonstration_script_does_the_task(scene, variant):
    """The scripted person opens both doors and puts the object on its table."""
    script = load_script(SCRIPTS[variant])
    sim = Sim(scene, script_layout(scene, script))
    m, d = sim.model, sim.data
    slide = m.jnt_qposadr[m.joint("sliding_door_slide").id]
    hinge = m.jnt_qposadr[m.joint("wardrobe_hinge").id]
    for _ in run_script(script, sim):
        pass
    sim.settle(1.0)
    assert d.qpos[slide] > 0.8, "the sliding door is open"
    assert math.degrees(d.qpos[hinge]) > 80, "the wardrobe is open"
    assert Truth(sim).success(), Truth(sim).success().reason
    sim.close()


def test_sample_logs_hold_both_pois_and_stay_small():
    for path in sorted(SAMPLES.glob("*.mcap")):
        assert path.stat().st_size < 8e6, path
        log = read_log(path)
        assert len(log.base_t) == len(log.poi_t) > 1000
        assert all(c.base is not None for c in log.commands)
        # The hand in the base's frame stays in the arm's reach; the base crosses two rooms.
        assert np.abs(log.poi[:, :2]).max() < 1.0
        assert np.ptp(log.base[:, 0]) > 3.0
        # A 1 Hz camera, plus a frame at each saliency mark (where compile perceives).
        frame_t = np.array([f.t for f in log.frames])
        for mark in log.marks:
            assert np.min(np.abs(frame_t - mark.t)) < 1e-6, mark
        assert len(log.scans) >= len(log.frames)


def test_tree_merges_up_to_the_grasp_then_branches_by_object(tree):
    t = load_tree(tree)
    assert t.params.perception.crop_frame == "base" and t.params.perception.remove_walls
    chain, node = [], ROOT
    while len(t.children(node)) == 1:
        e = t.children(node)[0]
        chain.append(e)
        node = e.child
    # Shared by both demonstrations: to the door, its handle, the pull, through the
    # doorway, the wardrobe's bar, the pull on its arc (base and hand), to the shelf.
    assert len(chain) >= 8 and all(e.support == 2 for e in chain)
    pois = {e.smc.action.poi for e in chain}
    assert pois == {"base", "hand"}
    assert any(e.smc.action.base_dmp is not None for e in chain), "two DMPs, one duration"
    handles = [e for e in chain if e.smc.action.event == "close"]
    assert len(handles) == 2 and all(e.smc.perception.cluster is not None for e in handles)
    # Then one branch per object, each grasping it first.
    branches = t.children(node)
    assert len(branches) == 2 and all(e.support == 1 for e in branches)
    assert all(e.smc.action.event == "close" for e in branches)
    p = t.params.perception
    names = {
        colour_name(
            dominant_rgb(e.smc.perception.cluster.histogram, p.hue_bins, p.sat_bins, p.val_bins)
        )
        for e in branches
    }
    assert "green" in names and len(names) == 2


def test_a_tucked_hand_keeps_the_taught_wrist(tree, scene):
    # Tucking the hand after the wardrobe's bar is a posture in the base's frame: a wrist
    # turned by the gripper's half turn holds the same way but swings the elbow in front
    # of the head camera, so the taught yaw is kept whatever the wrist's start.
    t = load_tree(tree)
    tucks = [e for e in t.edges if e.smc.action.goal_frame == "base" and e.smc.action.poi == "hand"]
    assert tucks
    policy = TreePolicy(t, scene.robot)
    base = np.array([4.05, 0.41, -0.08])
    for edge in tucks:
        a = edge.smc.action
        for start_yaw in (a.goal[3] + base[2] + 2.9, a.goal[3] + base[2] - 2.9):
            start = np.array([4.5, 0.1, 0.95, start_yaw])
            goal = policy.map_goal(a, None, start, edge.id, None, base)
            assert abs(math.remainder(goal[3] - base[2] - a.goal[3], 2 * math.pi)) < 1e-9


def test_layouts_move_the_wardrobe_and_what_rests_on_it(scene):
    rng = np.random.default_rng(7)
    (spec,) = scene.furniture
    for _ in range(50):
        lay = sample_layout(scene, rng)
        wx, wy, _, wyaw = lay["wardrobe"]
        assert spec.range_x[0] <= wx <= spec.range_x[1]
        assert spec.range_yaw[0] <= wyaw <= spec.range_yaw[1]
        obj = "green_can" if "green_can" in lay else "screwdriver"
        ox, oy, _, _ = lay[obj]
        # Back in the wardrobe's nominal frame, the object is where its ranges allow.
        c, s = math.cos(spec.pose[3] - wyaw), math.sin(spec.pose[3] - wyaw)
        dx, dy = ox - wx, oy - wy
        nx, ny = spec.pose[0] + c * dx - s * dy, spec.pose[1] + s * dx + c * dy
        o = scene.object(obj)
        assert o.range_x[0] - 1e-9 <= nx <= o.range_x[1] + 1e-9
        assert o.range_y[0] - 1e-9 <= ny <= o.range_y[1] + 1e-9


@pytest.mark.slow
def test_replay_on_a_random_layout(tree, tmp_path):
    """Start pose, wardrobe pose and the object's pose on its shelf randomised (seed 0):
    root to a leaf, one decision per SMC, each a child of the last one's node."""
    result = run_episode(tree, seed=0, output=tmp_path / "replay.mcap")
    assert result.outcome == "success", result.reason
    t = load_tree(tree)
    edges = {e.id: e for e in t.edges}
    chosen = [edges[str(d["chosen"])] for d in read_log(tmp_path / "replay.mcap").decisions]
    assert chosen[0].parent == ROOT and not t.children(chosen[-1].child)
    assert all(a.child == b.parent for a, b in zip(chosen, chosen[1:], strict=False))


@pytest.mark.slow
def test_small_campaign(tree):
    """6 random layouts (campaign seed 0): measured 5 of 6 (docs/figures.md: the 100-trial rate).
    A failure is a stop at a decision whose perception did not match (the object or the
    bar seen partly hidden); the robot never ends in a collision or with the object
    dropped."""
    summary = run_campaign(tree, trials=4, seed=0, workers=2)
    assert summary["successes"] >= 3, summary["failures"]
    causes = {cause for cause, n in summary["failures"].items() if n}
    assert causes <= {"no_contingent_smc"}, summary["failures"]


@pytest.mark.slow
def test_a_campaign_repeats_bit_for_bit(tree):
    """The same seed twice, each on 2 fresh worker processes: every trial's outcome, path,
    D_P of every candidate, mapped goals and final object poses are the same bits (the
    100-trial campaign of docs/figures.md flipped two trials between runs while open3d's ICP ran on
    2 threads)."""
    t, sc = resolve(tree, None)
    runs = [[r.repeatable() for r in run_trials(t, sc, trials=3, seed=0, workers=2)] for _ in "ab"]
    assert runs[0] == runs[1]
    assert all(r["decisions"] for r in runs[0])


def _move_wardrobe(sim: Sim, dx: float, dy: float, dyaw: float) -> None:
    """Shift the wardrobe (and the object on its shelf) while the robot works."""
    m, d = sim.model, sim.data
    b = m.body("wardrobe").id
    yaw0 = 2 * math.atan2(m.body_quat[b][3], m.body_quat[b][0])
    pivot = m.body_pos[b][:2].copy()
    m.body_pos[b][:2] = pivot + [dx, dy]
    m.body_quat[b] = [math.cos((yaw0 + dyaw) / 2), 0, 0, math.sin((yaw0 + dyaw) / 2)]
    for name in ("green_can", "screwdriver"):
        if name not in sim.present:
            continue
        adr = m.jnt_qposadr[m.body_jntadr[m.body(name).id]]
        rel = d.qpos[adr : adr + 2] - pivot
        c, s = math.cos(dyaw), math.sin(dyaw)
        d.qpos[adr : adr + 2] = (
            pivot + [dx, dy] + [c * rel[0] - s * rel[1], s * rel[0] + c * rel[1]]
        )
        q = np.zeros(4)
        mujoco.mju_mulQuat(
            q, np.array([math.cos(dyaw / 2), 0, 0, math.sin(dyaw / 2)]), d.qpos[adr + 3 : adr + 7]
        )
        d.qpos[adr + 3 : adr + 7] = q
    mujoco.mj_forward(m, d)


@pytest.mark.slow
def test_the_wardrobe_moves_between_two_decisions(tree, scene):
    """As in the paper's video: the wardrobe is pushed (4 cm, 3 cm, 3 deg) once the robot
    stands in front of it, before it decides to grasp the bar; the replay still succeeds."""
    sim = Sim(scene, layout_for(scene, 0))
    executor = TreeExecutor(load_tree(tree), Sensors(sim))
    policy = executor.policy
    moved = False
    while not policy.done:
        edges = policy.stack(policy.nodes).edges
        clusters = [e.smc.perception.cluster for e in edges if e.smc.action.event == "close"]
        if not moved and any(c is not None and c.centroid[0] > 4.0 for c in clusters):
            # Standing in front of the wardrobe, about to grasp its bar.
            _move_wardrobe(sim, 0.04, -0.03, math.radians(3))
            moved = True
        obs, _, _ = executor.observe()
        plan = policy.decide(obs)
        assert not plan.stopped, plan.reason
        executor.execute(plan)
        policy.advance(plan)
    sim.settle(1.0)
    assert moved
    assert Truth(sim).success(), Truth(sim).success().reason
    sim.close()


def test_inspect_shows_the_whole_trace(tree, tmp_path):
    """Base path, the hand's path in the world, scans, clusters at the decision points."""
    from test_inspect import _instances, read_rrd

    from smccli.inspect.recording import inspect

    demo = SAMPLES / "demo_can.mcap"
    inspect(tree, [demo], save=tmp_path / "loco.rrd")
    rec = next(iter(read_rrd(tmp_path / "loco.rrd").values()))
    path = np.asarray(_instances(rec["/world/poi/path"], "LineStrips3D:strips")[0])
    assert np.ptp(path[:, 0]) > 3.0, "the hand's path in the world crosses both rooms"
    assert 0.5 < np.median(path[:, 2]) < 1.2
    assert "Arrows3D" in rec["/world/base/heading"]["archetypes"]
    assert rec["/world/lidar/scan"]["rows"] > 0
    assert rec["/world/decisions/clusters"]["rows"] > 0
    assert any(p.startswith("/world/robot/") for p in rec)


@pytest.mark.slow
def test_a_handle_torn_from_the_hand_is_reported_as_slipped(tree, scene):
    """Once the hand holds the sliding door's handle, the door is yanked 25 cm open (as
    a person would): the handle leaves the closed hand. Evaluation's watch sees it and the
    episode's cause is handle_slipped, naming the door."""
    from smccli.execute.evaluation import HandleWatch, score

    layout = layout_for(scene, 0)
    sim = Sim(scene, layout)
    watch = HandleWatch(scene.doors)
    door = sim.model.jnt_qposadr[sim.model.joint("sliding_door_slide").id]
    yanked = []

    def on_step(cmd) -> None:
        watch.watch(Truth(sim), cmd)
        if not yanked and watch.holding("sliding_door") and sim.t > 0:
            sim.data.qpos[door] += 0.25
            mujoco.mj_forward(sim.model, sim.data)
            yanked.append(sim.t)

    executor = TreeExecutor(load_tree(tree), Sensors(sim, on_step=on_step), max_time=40.0)
    outcome, reason, _, actions, _ = executor.run()
    verdict = score(
        sim, scene, layout, outcome=outcome, reason=reason, actions=actions, slips=watch.slipped
    )
    sim.close()
    assert yanked and watch.slipped and watch.slipped[0].startswith("sliding_door")
    assert verdict.outcome == "handle_slipped", (verdict.outcome, verdict.reason)
