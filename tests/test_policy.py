"""TreePolicy, Algorithm 2 as a library: a control loop of our own around it (as a robot's
would be, docs/on_a_robot.md) drives MuJoCo through the robot's sensors only, reaches a
leaf, meets the scene's success criterion, and decides exactly as TreeExecutor does."""

from __future__ import annotations

import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from conftest import SAMPLE_LOGS  # noqa: E402

from smccli.errors import SmcError, TreeError  # noqa: E402
from smccli.execute import Observation, Plan, TreePolicy  # noqa: E402
from smccli.execute.episode import FINAL_SETTLE, episode, layout_for, resolve  # noqa: E402
from smccli.execute.executor import ARRIVAL_TOLERANCE, MAX_HOLD  # noqa: E402
from smccli.learn.compile import compile_logs  # noqa: E402
from smccli.learn.tree import ROOT, Tree  # noqa: E402
from smccli.perception.scan import Scan2D  # noqa: E402
from smccli.world.robot_model import RobotModel  # noqa: E402
from smccli.world.scene import Scene, load_scene  # noqa: E402
from smccli.world.sensors import PoiCommand  # noqa: E402
from smccli.world.sim import Sim  # noqa: E402
from smccli.world.truth import Truth  # noqa: E402


@pytest.fixture(scope="module")
def bench(tmp_path_factory) -> tuple[Tree, Scene]:
    path = tmp_path_factory.mktemp("policy") / "bench_pick.json"
    compile_logs([SAMPLE_LOGS / "bench_pick" / "demo.mcap"], path)
    return resolve(path, None)


@pytest.fixture(scope="module")
def rooms(tmp_path_factory) -> tuple[Tree, Scene]:
    path = tmp_path_factory.mktemp("policy") / "rooms.json"
    compile_logs([SAMPLE_LOGS / "rooms" / f"demo{i}.mcap" for i in (1, 2)], path)
    return resolve(path, None)


# --- the robot's side: sensors in, POI and gripper commands out ----------------------------


class Robot:
    """A robot seen as a user's runtime sees it: sensor readings and a Cartesian command."""

    def __init__(self, scene: Scene, layout: dict) -> None:
        self.sim = Sim(scene, layout)
        self.period = self.sim.control_period
        # The self-filter's kinematic copy, from the MJCF and the joint names (once).
        self.body = RobotModel.from_mjcf(scene.mjcf, scene.robot.joint_names)

    def observe(self) -> Observation:
        s = self.sim
        if s.lidar_pose() is None:  # an arm: camera, joints for the self-filter, POI
            joints = s.joint_state()
            return Observation(
                t=s.t,
                poi=s.poi(),
                camera=s.render_camera(),
                robot_geometry=self.body.geometry_for(joints.position),
            )
        r = s.lidar()  # a mobile base: camera (room colours), scan, odometry
        assert r is not None
        return Observation(
            t=s.t,
            poi=s.poi(),
            camera=s.render_camera(),
            scan=Scan2D(r.ranges, r.angle_min, r.angle_increment, r.range_max),
            lidar_pose=s.lidar_pose(),
        )

    def command(self, pose: np.ndarray, gripper: float) -> None:
        self.sim.step(PoiCommand(self.sim.t, pose, gripper))

    def arrive(self, pose: np.ndarray, gripper: float) -> bool:
        """Hold ``pose`` until the POI is there (at most MAX_HOLD)."""
        for _ in range(round(MAX_HOLD / self.period)):
            if np.linalg.norm(self.sim.poi()[:3] - pose[:3]) < ARRIVAL_TOLERANCE:
                return True
            self.command(pose, gripper)
        return False

    def grip(self, pose: np.ndarray, opening: float) -> None:
        """Command ``opening`` and wait until the fingers stop."""
        still, t0 = 0, self.sim.t
        while True:
            self.command(pose, opening)
            still = 0 if abs(self.sim.gripper_speed()) > 0.02 else still + 1
            if (self.sim.t - t0 > 0.15 and still >= 10) or self.sim.t - t0 > 3.0:
                return

    def execute(self, plan: Plan) -> None:
        assert plan.goal is not None and plan.gripper_start is not None
        assert plan.gripper_end is not None
        grip, k = plan.gripper_start, len(plan.poses) - 1
        if plan.midway:
            assert plan.switch_index is not None
            k = plan.switch_index
        for pose in plan.poses[1 : k + 1]:
            self.command(pose, grip)
        if plan.midway:
            self.arrive(plan.poses[k], grip)
            self.grip(plan.poses[k], plan.gripper_end)
            grip = plan.gripper_end
            for pose in plan.poses[k + 1 :]:
                self.command(pose, grip)
        self.arrive(plan.goal, grip)
        if plan.switch_index is not None and not plan.midway:
            self.grip(plan.goal, plan.gripper_end)


def run_policy(tree: Tree, scene: Scene, layout: dict) -> tuple[list[Plan], bool, TreePolicy]:
    robot = Robot(scene, layout)
    policy = TreePolicy(tree, scene.robot, scene.model())
    plans = []
    try:
        while not policy.done:
            plan = policy.decide(robot.observe(), control_period=robot.period)
            assert not plan.stopped and not plan.done, plan.reason
            plans.append(plan)
            robot.execute(plan)
            policy.advance(plan)
            assert len(plans) < 10
        robot.sim.settle(FINAL_SETTLE)
        # Evaluation, after control: the scene's success criterion from the simulator's truth.
        success = bool(Truth(robot.sim).success())
        final = robot.observe()
    finally:
        robot.sim.close()
    last = policy.decide(final)
    assert last.done and last.decision is None and "leaf" in last.reason
    return plans, success, policy


# --- tests ---------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [1, 4, 9])
def test_own_loop_reaches_a_leaf_and_decides_as_the_executor(bench, seed: int) -> None:
    tree, scene = bench
    layout = layout_for(scene, seed, 0)
    plans, success, policy = run_policy(tree, scene, layout)
    assert success and policy.done
    # The own loop does not look again while an action runs: nor does the reference.
    reference = episode(tree, scene, layout, seed=seed, look_period=0.0)
    assert reference.outcome == "success", reference.reason
    assert [p.edge for p in plans] == list(reference.path) == ["e1", "e2"]
    for plan, ref in zip(plans, reference.decisions, strict=True):
        dec = plan.decision
        assert dec is not None and plan.goal is not None and ref.mapped_goal is not None
        assert dec.chosen == ref.chosen == plan.edge and dec.nodes == ref.nodes
        assert [c.d_p for c in dec.candidates] == pytest.approx(
            [c.d_p for c in ref.candidates], abs=1e-9
        )
        np.testing.assert_allclose(plan.goal, ref.mapped_goal, rtol=0, atol=1e-9)
        assert dec.duration == pytest.approx(ref.duration, abs=1e-9)
        # The trajectory: from the POI to the mapped goal, one pose per control period.
        assert plan.poses.shape == (len(plan.times), 4) and plan.times[0] == 0.0
        np.testing.assert_allclose(np.diff(plan.times), plan.duration / (len(plan.times) - 1))
        assert abs(plan.times[1] - 0.01) < 1e-3 and plan.times[-1] == pytest.approx(plan.duration)
        np.testing.assert_allclose(plan.poses[-1], plan.goal, atol=1e-6)
    grasp, place = plans
    assert grasp.event == "close" and grasp.gripper_start == 1.0 and grasp.gripper_end == 0.0
    assert place.event == "open" and place.gripper_start == 0.0 and place.gripper_end == 1.0
    for p in plans:
        assert p.switch_index is not None and p.gripper_switch == p.times[p.switch_index]
    # The white box is grasped where it is (decided from the camera only).
    assert np.hypot(*(grasp.goal[:2] - np.array(layout["white_box"][:2]))) < 0.01


def test_mobile_base_reaches_the_arrows_goal(rooms) -> None:
    tree, scene = rooms
    layout = layout_for(scene, 2, 0)
    plans, success, _ = run_policy(tree, scene, layout)
    assert success
    reference = episode(tree, scene, layout, seed=2)
    assert reference.outcome == "success", reference.reason
    assert [p.edge for p in plans] == list(reference.path)
    first = plans[0]
    assert first.decision is not None and first.goal is not None
    assert first.scan_alignment is not None and first.scan_alignment.shape == (3, 3)
    terms = dict(first.decision.candidates[0].terms)
    assert {"room", "scan", "icp_fitness"} <= set(terms)
    # The first decision sees what the executor saw (ICP's last bits vary run to run).
    np.testing.assert_allclose(first.goal, reference.decisions[0].mapped_goal, atol=1e-9)
    # Later ones follow our own loop, which does not relocalize while driving.
    for plan, ref in zip(plans, reference.decisions, strict=True):
        assert plan.goal is not None and ref.mapped_goal is not None
        assert np.linalg.norm(plan.goal[:2] - ref.mapped_goal[:2]) < 0.05


def test_no_contingent_smc_stops_with_the_distances_and_stays(bench) -> None:
    tree, scene = bench
    sim = Sim(scene, {"orange_box": [0.45, 0.4, 0.035, 0.0]})  # no white box on the table
    try:
        js = sim.joint_state()
        body = RobotModel.from_mjcf(scene.mjcf, js.names)
        obs = Observation(sim.t, sim.poi(), sim.render_camera(), body.geometry_for(js.position))
    finally:
        sim.close()
    policy = TreePolicy(tree, scene.robot)
    plan = policy.decide(obs)
    assert plan.stopped and plan.stop == "no_contingent_smc" and not plan.done
    assert plan.edge is None and plan.goal is None and len(plan.poses) == 0
    assert plan.decision is not None and plan.decision.chosen is None
    assert "e1 d_p=" in plan.reason and "\n" not in plan.reason
    assert policy.nodes == (ROOT,) and not policy.done
    with pytest.raises(SmcError, match="stopped"):
        policy.advance(plan)


def test_missing_readings_and_wrong_robot_are_one_line_errors(bench) -> None:
    tree, scene = bench
    policy = TreePolicy(tree, scene.robot)
    with pytest.raises(SmcError) as err:
        policy.decide(Observation(t=0.0, poi=np.array([0.3, 0.0, 0.3, 0.0])))
    msg = str(err.value)
    assert "no camera" in msg and "e1" in msg and "Observation.camera" in msg and "\n" not in msg
    with pytest.raises(SmcError, match="poi must be 4 finite numbers"):
        Observation(t=0.0, poi=np.array([0.3, 0.0, 0.3]))
    with pytest.raises(TreeError, match="taught on robot 'arm'"):
        TreePolicy(tree, load_scene("rooms").robot)


def test_rooms_tree_needs_the_scan(rooms) -> None:
    tree, scene = rooms
    policy = TreePolicy(tree, scene.robot)
    sim = Sim(scene, layout_for(scene, 2, 0))
    try:
        obs = Observation(t=sim.t, poi=sim.poi(), camera=sim.render_camera())
    finally:
        sim.close()
    with pytest.raises(SmcError, match=r"no scan: SMC e1 at node n0 match on a lidar scan"):
        policy.decide(obs)
