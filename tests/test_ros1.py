"""smc run --ros1 against a real roscore: `smc sim --ros1` is the robot, `smc run --ros1`
drives it; both are real subprocesses on a master of their own (127.0.0.1, a free port).

The tree's decisions over ROS equal `smc replay`'s on the same layouts, and the node stops
the robot on stale sensors, a lost transform, an unreachable goal, no contingent SMC and
Ctrl-C, with the reason published and printed and its exit code."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import sample_log_paths, smc_start
from zygote import Command

from smccli.ros.master import roscore
from smccli.ros.node import EXIT_CODES

pytestmark = pytest.mark.skipif(
    shutil.which("roscore") is None or not Path("/usr/lib/python3/dist-packages/rospy").is_dir(),
    reason="ROS 1 (roscore, python3-rospy) is not installed: make system-deps",
)

MONITOR = """
import json, sys, time
sys.path.append("/usr/lib/python3/dist-packages")
import rospy
from geometry_msgs.msg import PoseStamped
from std_msgs.msg import String
out = open(sys.argv[1], "a", buffering=1)
def note(topic, data):
    out.write(json.dumps({"topic": topic, "wall": time.time(), "data": data}) + "\\n")
rospy.init_node("smc_test_monitor", anonymous=True)
for t in ("/smc/state", "/smc/decision"):
    rospy.Subscriber(t, String, lambda m, t=t: note(t, m.data), queue_size=1000, tcp_nodelay=True)
rospy.Subscriber("/smc/poi_target", PoseStamped, lambda m: note("/smc/poi_target",
    m.header.stamp.to_nsec()), queue_size=10000, tcp_nodelay=True)
note("ready", "")
rospy.spin()
"""

RELAY = """
import sys
sys.path.append("/usr/lib/python3/dist-packages")
import rospy
from sensor_msgs.msg import Image
rospy.init_node("camera_relay", anonymous=True)
pub = rospy.Publisher(sys.argv[2], Image, queue_size=10)
rospy.Subscriber(sys.argv[1], Image, pub.publish, queue_size=10, tcp_nodelay=True)
rospy.spin()
"""

TF_RELAY = """
import sys
sys.path.append("/usr/lib/python3/dist-packages")
import rospy
from tf2_msgs.msg import TFMessage
rospy.init_node("tf_relay", anonymous=True)
pub = rospy.Publisher("/tf", TFMessage, queue_size=100)
def relay(msg):
    out = [t for t in msg.transforms if t.child_frame_id == sys.argv[1]]
    for t in out:
        t.child_frame_id = sys.argv[2]
    if out:
        pub.publish(TFMessage(out))
rospy.Subscriber("/tf", TFMessage, relay, queue_size=100, tcp_nodelay=True)
rospy.spin()
"""
"""Republishes one frame of /tf under another name: the transform's own publisher."""


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory) -> Iterator[dict[str, str]]:
    """A roscore of its own on 127.0.0.1 and the environment that reaches it."""
    with roscore(tmp_path_factory.mktemp("ros")) as env:
        yield env


@pytest.fixture(scope="module")
def trees(tmp_path_factory) -> dict[str, Path]:
    """bench_pick's, weigh_sort's (a scale) and rooms' sample demonstrations compiled."""
    from smccli.learn.compile import compile_logs

    root = tmp_path_factory.mktemp("ros_trees")
    out = {}
    for scene in ("bench_pick", "weigh_sort", "rooms"):
        out[scene] = root / f"{scene}.json"
        compile_logs(sample_log_paths(scene), out[scene])
    return out


def _map(path: Path, scene: str, **edits: object) -> Path:
    """The sim's topic map of ``scene``, with ``edits`` (dotted keys) changed."""
    from smccli.ros.sim_robot import sim_topic_map
    from smccli.world.scene import load_scene

    data = sim_topic_map(load_scene(scene))
    for key, value in edits.items():
        *parents, last = key.split(".")
        node = data
        for p in parents:
            node = node[p]
        node[last] = value
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


class Robot:
    """`smc sim --ros1` running: its process and its verdict once stopped."""

    def __init__(self, env: dict[str, str], tmp: Path, scene: str, *args: str) -> None:
        self.report = tmp / f"sim_{scene}.json"
        self.log = tmp / f"sim_{scene}.log"
        self.log.write_text("")  # read below before the command may have opened it
        self.proc = smc_start(
            "sim",
            "--ros1",
            "--scene",
            scene,
            "--report",
            self.report,
            "--force",
            *args,
            out=self.log,
            env=env,
        )
        deadline = time.monotonic() + 120
        while "running" not in self.log.read_text():  # it says so once it publishes
            assert self.proc.poll() is None and time.monotonic() < deadline, self.log.read_text()
            time.sleep(0.1)

    def stop(self) -> dict:
        self.proc.send_signal(signal.SIGINT)
        self.proc.wait(timeout=60)
        assert self.proc.returncode == 0, self.log.read_text()
        return json.loads(self.report.read_text())


class Monitor:
    """A subscriber to /smc/state, /smc/decision and the POI targets, logging to a file."""

    def __init__(self, env: dict[str, str], tmp: Path) -> None:
        self.path = tmp / "monitor.jsonl"
        self.path.write_text("")
        self.proc = subprocess.Popen([sys.executable, "-c", MONITOR, str(self.path)], env=env)
        self.wait_for(lambda r: r["topic"] == "ready")

    def records(self) -> list[dict]:
        return [json.loads(line) for line in self.path.read_text().splitlines() if line]

    def wait_for(self, match, timeout: float = 120.0) -> dict:  # noqa: ANN001
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for r in self.records():
                if match(r):
                    return r
            time.sleep(0.05)
        raise AssertionError("monitor: nothing matched")

    def close(self) -> None:
        self.proc.send_signal(signal.SIGINT)
        self.proc.wait(timeout=20)


def _run(env: dict[str, str], tree: Path, topics: Path, report: Path) -> Command:
    out = report.with_name(report.stem + ".out")
    return smc_start(
        "run",
        tree,
        "--ros1",
        "--topics",
        topics,
        "--report",
        report,
        out=out,
        err=out.with_suffix(".err"),
        env=env,
    )


def _same_decisions(ros: list[dict], replay: list[dict]) -> None:
    assert [d["chosen"] for d in ros] == [d["chosen"] for d in replay]
    for a, b in zip(ros, replay, strict=True):
        if b["mapped_goal"] is not None:
            assert np.allclose(a["mapped_goal"][:3], b["mapped_goal"][:3], atol=1e-3)
            assert abs(a["mapped_goal"][3] - b["mapped_goal"][3]) < 1e-3


JOINT_SPACE = {"run": {"arm": "/arm_controller/command", "gripper": "/gripper/command"}}
"""An arm commanded by joint trajectories instead of POI targets."""


COMPRESSED = {
    "topics.color": "/camera/color/image_raw/compressed",
    "topics.depth": "/camera/depth/image_raw/compressedDepth",
}
"""image_transport's compressed colour (PNG) and compressedDepth (16UC1 PNG, millimetres)."""


@pytest.mark.parametrize(
    ("scene", "seeds", "edits"),
    [
        ("bench_pick", (3, 5), {}),
        ("bench_pick", (7,), JOINT_SPACE),
        ("bench_pick", (9,), COMPRESSED),
        ("weigh_sort", (3,), {}),
        ("rooms", (3,), {}),
    ],
    ids=["bench_pick", "bench_pick-joint-space", "bench_pick-compressed", "weigh_sort", "rooms"],
)
def test_tree_runs_the_robot_as_replay(ros_env, trees, tmp_path, scene, seeds, edits) -> None:
    """End to end over ROS: the task succeeds and every decision (edge, goal within 1 mm)
    is replay's on the same layout; an arm taking POI targets, or joint targets (the
    node's Cartesian controller makes them), its camera raw or compressed (depth in
    millimetres: goals move by a fraction of one), a scale's weight, or a mobile base."""
    from smccli.execute.episode import run_episode

    topics = _map(tmp_path / "map.yaml", scene, **edits)
    for seed in seeds:
        robot = Robot(ros_env, tmp_path, scene, "--seed", str(seed), "--topics", str(topics))
        report = tmp_path / f"run_{seed}.json"
        node = _run(ros_env, trees[scene], topics, report)
        out, err = node.communicate(timeout=600)
        verdict = robot.stop()
        assert node.returncode == 0, out + err
        assert "success: leaf reached" in out
        assert verdict["success"], verdict["reason"]
        ros = json.loads(report.read_text())
        replay = run_episode(trees[scene], seed=seed)
        assert replay.success
        _same_decisions(ros["decisions"], [d.to_json() for d in replay.decisions])
        assert verdict["steps"] == ros["commands"]  # the robot moved by the node's commands only
        assert len(ros["image_to_command_ms"]) == len(ros["decisions"])


def _stopped(monitor: Monitor, node: Command, robot: Robot, stop: str) -> str:
    """The node ended with ``stop``: its exit code, the reason printed and published, and
    no command after it (the robot stepped once per command the node counted)."""
    out, err = node.communicate(timeout=120)
    assert node.returncode == EXIT_CODES[stop], out + err
    assert stop in out
    state = monitor.wait_for(lambda r: r["topic"] == "/smc/state" and "stopped" in r["data"])
    assert f"stopped ({stop})" in state["data"]
    verdict = robot.stop()
    monitor.close()
    report = json.loads(Path(node.args[node.args.index("--report") + 1]).read_text())
    assert report["outcome"] == stop and report["exit_code"] == EXIT_CODES[stop]
    assert verdict["steps"] == report["commands"]  # nothing moved it after the node stopped
    return out


def test_stops_when_the_camera_publisher_dies(ros_env, trees, tmp_path) -> None:
    sim_map = _map(tmp_path / "sim.yaml", "bench_pick", **{"topics.color": "/sim/color"})
    topics = _map(tmp_path / "map.yaml", "bench_pick")
    relay = subprocess.Popen(
        [sys.executable, "-c", RELAY, "/sim/color", "/camera/color/image_raw"], env=ros_env
    )
    robot = Robot(ros_env, tmp_path, "bench_pick", "--seed", "3", "--topics", str(sim_map))
    monitor = Monitor(ros_env, tmp_path)
    node = _run(ros_env, trees["bench_pick"], topics, tmp_path / "run.json")
    monitor.wait_for(lambda r: r["topic"] == "/smc/decision")
    relay.kill()  # the camera's publisher dies mid-task
    relay.wait()
    out = _stopped(monitor, node, robot, "stale_sensors")
    assert "color on /camera/color/image_raw" in out


def test_stops_without_the_poi_transform(ros_env, trees, tmp_path) -> None:
    topics = _map(
        tmp_path / "map.yaml", "bench_pick", **{"topics.poi": {"frame": "tool0"}, "run.wait_s": 2.0}
    )
    robot = Robot(ros_env, tmp_path, "bench_pick", "--seed", "3")
    monitor = Monitor(ros_env, tmp_path)
    node = _run(ros_env, trees["bench_pick"], topics, tmp_path / "run.json")
    out = _stopped(monitor, node, robot, "tf_lost")
    assert "tool0" in out


def test_stops_when_the_transform_publisher_dies(ros_env, trees, tmp_path) -> None:
    """The POI's transform comes from a publisher of its own, which dies mid-task: the
    joints and the camera keep coming, the transform does not."""
    relay = subprocess.Popen([sys.executable, "-c", TF_RELAY, "tool", "relayed_tool"], env=ros_env)
    topics = _map(tmp_path / "map.yaml", "bench_pick", **{"topics.poi": {"frame": "relayed_tool"}})
    robot = Robot(ros_env, tmp_path, "bench_pick", "--seed", "3")
    monitor = Monitor(ros_env, tmp_path)
    node = _run(ros_env, trees["bench_pick"], topics, tmp_path / "run.json")
    monitor.wait_for(lambda r: r["topic"] == "/smc/poi_target")  # it moves the robot
    relay.kill()
    relay.wait()
    out = _stopped(monitor, node, robot, "tf_lost")
    assert "relayed_tool" in out


@pytest.mark.parametrize(
    ("white_box", "stop"),
    [([0.85, -0.05, 0.025, 0.0], "target_unreachable"), (None, "no_contingent_smc")],
)
def test_stops_at_a_decision(ros_env, trees, tmp_path, white_box, stop) -> None:
    """A goal out of reach, or nothing to pick: the policy's stop, before any command."""
    layout = {"orange_box": [0.45, 0.4, 0.035, 0.0]}
    if white_box is not None:
        layout["white_box"] = white_box
    (tmp_path / "layout.yaml").write_text(yaml.safe_dump(layout))
    topics = _map(tmp_path / "map.yaml", "bench_pick")
    robot = Robot(ros_env, tmp_path, "bench_pick", "--layout", str(tmp_path / "layout.yaml"))
    monitor = Monitor(ros_env, tmp_path)
    node = _run(ros_env, trees["bench_pick"], topics, tmp_path / "run.json")
    _stopped(monitor, node, robot, stop)
    decisions = [r for r in monitor.records() if r["topic"] == "/smc/decision"]
    assert len(decisions) == 1
    report = json.loads((tmp_path / "run.json").read_text())
    assert report["commands"] == 0
    assert (report["decisions"][0]["chosen"] is None) == (stop == "no_contingent_smc")


def test_ctrl_c_stops_the_robot(ros_env, trees, tmp_path) -> None:
    topics = tmp_path / "served.yaml"  # the map the sim says it serves
    robot = Robot(ros_env, tmp_path, "bench_pick", "--seed", "3", "--write-map", str(topics))
    expected = _map(tmp_path / "map.yaml", "bench_pick")
    assert yaml.safe_load(topics.read_text()) == yaml.safe_load(expected.read_text())
    monitor = Monitor(ros_env, tmp_path)
    node = _run(ros_env, trees["bench_pick"], topics, tmp_path / "run.json")
    monitor.wait_for(lambda r: r["topic"] == "/smc/poi_target")
    node.send_signal(signal.SIGINT)
    _stopped(monitor, node, robot, "interrupted")


def test_without_rospy_one_line_names_the_packages(monkeypatch, tmp_path) -> None:
    """rospy is looked for at the end of sys.path only; missing, it is an SmcError (exit 2)
    naming what to install."""
    from smccli.errors import SmcError
    from smccli.ros import ros1

    ros = ("rospy", "geometry_msgs", "sensor_msgs", "trajectory_msgs")
    for name in [n for n in sys.modules if n.split(".")[0] in ros]:  # imported before: gone
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setattr(ros1, "DIST_PACKAGES", str(tmp_path))
    monkeypatch.setattr(sys, "path", [p for p in sys.path if "dist-packages" not in p])
    with pytest.raises(SmcError, match="apt-get install ros-core python3-rospy"):
        ros1.import_rospy()
    assert sys.path[-1] == str(tmp_path)  # appended last: it never shadows the venv


def test_a_map_without_run_is_refused(tmp_path) -> None:
    from smccli.errors import SceneError
    from smccli.ros.run import run_map

    path = _map(tmp_path / "map.yaml", "bench_pick")
    data = yaml.safe_load(path.read_text())
    del data["run"]
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(SceneError, match="no `run:` section"):
        run_map(path)


def test_joint_states_of_two_publishers_merge_by_name(tmp_path) -> None:
    """An arm's driver and its gripper's publish on one topic: the robot's clock starts
    once every joint was heard, the gripper's joints renamed by the map's ``joints``."""
    from rosbags.typesys import Stores, get_typestore

    from smccli.logs.topic_map import load_topic_map
    from smccli.ros.inbox import Inbox
    from smccli.world.scene import load_scene

    robot = load_scene("bench_pick").robot
    assert robot.gripper is not None
    renamed = {f"driver_{j}": j for j in robot.gripper.joints}
    path = _map(tmp_path / "map.yaml", "bench_pick", joints=renamed)
    inbox = Inbox(load_topic_map(path), robot)
    store = get_typestore(Stores.ROS1_NOETIC)
    JointState = store.types["sensor_msgs/msg/JointState"]
    Header, Time = store.types["std_msgs/msg/Header"], store.types["builtin_interfaces/msg/Time"]

    def message(names: list[str], positions: list[float], ns: int) -> object:
        values = np.array(positions, dtype=float)
        header = Header(seq=0, stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="")
        return JointState(header, names, values, np.zeros_like(values), np.array([]))

    arm = list(robot.arm_joints)
    inbox.add("/joint_states", message(arm, [0.1 * i for i in range(len(arm))], 10**9), 0.0)
    assert inbox.joint_stamp is None  # the fingers are not heard yet
    fingers = list(renamed)
    inbox.add("/joint_states", message(fingers, [0.02] * len(fingers), 10**9 + 5_000_000), 0.0)
    assert inbox.joint_stamp == 10**9 + 5_000_000
    js = inbox.joint_state()
    assert js.names == robot.joint_names
    assert np.allclose(js.position, [0.1 * i for i in range(len(arm))] + [0.02] * len(fingers))


def test_a_transform_that_stops_moving_stops_the_robot(tmp_path) -> None:
    """The POI's moving transform not updated for longer than ``stale_s`` on the robot's
    clock while the joints and the camera keep coming: tf_lost. (The node's checks, with
    the messages handed in directly instead of over a master.)"""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from smccli.logs.topic_map import load_topic_map
    from smccli.ros.inbox import Inbox
    from smccli.ros.node import RobotSensors, RobotStop
    from smccli.world.scene import load_scene

    scene = load_scene("bench_pick")
    m = load_topic_map(_map(tmp_path / "map.yaml", "bench_pick", **{"run.wait_s": 0.3}))
    assert m.run is not None
    store = get_typestore(Stores.ROS1_NOETIC)  # as the node's decoder: TFMessage registered
    tf_text = "geometry_msgs/TransformStamped[] transforms"
    store.register(get_types_from_msg(tf_text, "tf2_msgs/msg/TFMessage"))
    T = store.types

    class Bus:  # the node's middleware, in process
        interrupted = False
        inbox = Inbox(m, scene.robot)

    def header(ns: int, frame: str = "world") -> object:
        stamp = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)

    def tf(ns: int, child: str) -> object:
        v, q = T["geometry_msgs/msg/Vector3"](0.4, 0, 0.3), T["geometry_msgs/msg/Quaternion"]
        tr = T["geometry_msgs/msg/Transform"](v, q(0, 0, 0, 1))
        stamped = T["geometry_msgs/msg/TransformStamped"](header(ns), child, tr)
        return T["tf2_msgs/msg/TFMessage"]([stamped])

    def readings(ns: int) -> None:
        q = np.zeros(len(scene.robot.joint_names))
        names = list(scene.robot.joint_names)
        image = T["sensor_msgs/msg/Image"]
        pixels = np.zeros(4, dtype=np.uint8)
        for topic in ("/camera/color/image_raw", "/camera/depth/image_raw"):
            msg = image(header(ns, "camera"), 1, 1, "32FC1", 0, 4, pixels)
            Bus.inbox.add(topic, msg, 0.0)
        msg = T["sensor_msgs/msg/JointState"](header(ns), names, q, q, q)
        Bus.inbox.add("/joint_states", msg, 0.0)

    sensors = RobotSensors(Bus(), scene, m, m.run)  # type: ignore[arg-type]
    Bus.inbox.add("/tf_static", tf(0, "camera"), 0.0)
    Bus.inbox.add("/tf", tf(10**9, "tool"), 0.0)
    readings(10**9)
    sensors._check()
    assert sensors.poi()[:3].tolist() == [0.4, 0.0, 0.3]
    readings(2 * 10**9)  # a second later: the tool's transform did not come again
    with pytest.raises(RobotStop) as stop:
        sensors._check()  # after wait_s: it was not merely in flight
    assert stop.value.stop == "tf_lost" and "'tool'" in stop.value.reason
    late = threading.Timer(0.1, Bus.inbox.add, ("/tf", tf(2 * 10**9, "tool"), 0.0))
    late.start()  # in flight: it comes within wait_s, and the robot goes on
    sensors._check()
    late.join()
