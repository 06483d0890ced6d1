"""Bags as labs record them, written by another library (``rosbags``' rosbag1 and rosbag2
writers, not smc's exporter): a rosbag2 directory in sqlite3 or MCAP, split into several
files or not, a ROS 1 bag, depth through image_transport's compressedDepth, the gripper's
joints from a publisher of its own, a driver's joint names, marks from a joystick button.
Each compiles into the native log's tree; what cannot be read is one line, exit 2."""

from __future__ import annotations

import dataclasses
import struct
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import yaml
from conftest import SAMPLE_LOGS, smc
from mcap.reader import make_reader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore
from test_inspect import read_rrd
from test_ros2_bag import _chain, _world_goal

from smccli.errors import LogError
from smccli.learn.compile import compile_logs
from smccli.logs.ros2_bag import parse_topic_map, read_ros2_bag
from smccli.logs.ros2_export import export_ros2
from smccli.logs.ros2_msgs import export_map

SCENE = "bench_pick"
NATIVE = SAMPLE_LOGS / SCENE / "demo.mcap"
TS = get_typestore(Stores.ROS2_HUMBLE)
Message = tuple[str, str, int, Any]
"""(topic, type, log time [ns], message as rosbags' dataclass)."""


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> tuple[list[Message], dict[str, Any]]:
    """The native demo's messages (through smc's exporter, then decoded by rosbags) and
    the topic map ``smc export`` writes beside them."""
    bag = tmp_path_factory.mktemp("export") / "demo.mcap"
    export_ros2(NATIVE, bag)
    out: list[Message] = []
    with bag.open("rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            assert schema is not None
            msg = TS.deserialize_cdr(message.data, schema.name)
            out.append((channel.topic, schema.name, message.log_time, msg))
    topics = sorted({m[0] for m in out})
    return out, export_map(SCENE, topics)


@pytest.fixture(scope="module")
def native_tree(tmp_path_factory):
    return compile_logs([NATIVE], tmp_path_factory.mktemp("native") / "tree.json").tree


def write_rosbag2(
    folder: Path, messages: list[Message], storage: StoragePlugin, parts: int = 1
) -> Path:
    """A rosbag2 directory by rosbags' writer; ``parts`` > 1 splits it in time as
    ``ros2 bag record --max-bag-duration`` does (each part a bag of its own, then one
    metadata.yaml listing every file; /tf_static only in the first part)."""
    folder.mkdir(parents=True)
    cut = np.array_split(np.arange(len(messages)), parts)
    infos = []
    for k, idx in enumerate(cut):
        part = folder.parent / f"{folder.name}_part{k}"
        with Writer2(part, version=8, storage_plugin=storage) as w:
            conns: dict[str, Any] = {}
            for i in idx:
                topic, msgtype, t_ns, msg = messages[i]
                if topic not in conns:
                    conns[topic] = w.add_connection(topic, msgtype, typestore=TS)
                w.write(conns[topic], t_ns, TS.serialize_cdr(msg, msgtype))
        meta = yaml.safe_load((part / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        for f in meta["relative_file_paths"]:
            (part / f).rename(folder / f"{folder.name}_{k}{Path(f).suffix}")
        infos.append(meta)
        for f in part.iterdir():
            f.unlink()
        part.rmdir()
    info = infos[0]
    info["relative_file_paths"] = [
        f"{folder.name}_{k}{Path(i['relative_file_paths'][0]).suffix}" for k, i in enumerate(infos)
    ]
    info["files"] = [
        {**f, "path": p}
        for i, p in zip(infos, info["relative_file_paths"], strict=True)
        for f in i["files"]
    ]
    counts: dict[str, Any] = {}
    for i in infos:
        for t in i["topics_with_message_count"]:
            name = t["topic_metadata"]["name"]
            if name in counts:
                counts[name]["message_count"] += t["message_count"]
            else:
                counts[name] = dict(t)
    info["topics_with_message_count"] = list(counts.values())
    info["message_count"] = sum(i["message_count"] for i in infos)
    end = max(
        i["starting_time"]["nanoseconds_since_epoch"] + i["duration"]["nanoseconds"] for i in infos
    )
    info["duration"]["nanoseconds"] = end - info["starting_time"]["nanoseconds_since_epoch"]
    (folder / "metadata.yaml").write_text(yaml.safe_dump({"rosbag2_bagfile_information": info}))
    return folder


def _ros1_store() -> Any:
    """ROS 1 Noetic's types, with tf2_msgs' TFMessage (not in rosbags' store)."""
    from rosbags.typesys import get_types_from_msg

    ts = get_typestore(Stores.ROS1_NOETIC)
    tf = get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage")
    ts.register(tf)
    return ts


def to_ros1(ts1: Any, msg: Any) -> Any:
    """A ROS 2 message as its ROS 1 type: the same fields (CameraInfo's K for k, ...),
    a Header's seq 0."""
    cls = ts1.types[msg.__msgtype__]
    values = {}
    for f in dataclasses.fields(cls):
        if f.name == "__msgtype__":
            continue
        v = getattr(msg, f.name, getattr(msg, f.name.lower(), 0 if f.name == "seq" else None))
        if hasattr(v, "__msgtype__"):
            v = to_ros1(ts1, v)
        elif isinstance(v, list) and v and hasattr(v[0], "__msgtype__"):
            v = [to_ros1(ts1, x) for x in v]
        values[f.name] = v
    return cls(**values)


def write_rosbag1(path: Path, messages: list[Message]) -> Path:
    """A ROS 1 bag by rosbags' writer, in ROS 1's types and encoding."""
    ts1 = _ros1_store()
    with Writer1(path) as w:
        conns: dict[str, Any] = {}
        for topic, msgtype, t_ns, msg in messages:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=ts1)
            w.write(conns[topic], t_ns, ts1.serialize_ros1(to_ros1(ts1, msg), msgtype))
    return path


def same_tree(tree, native) -> None:
    """The native tree: same chain and supports, goals within 1 mm."""
    assert _chain(tree) == _chain(native)
    for a, b in zip(
        sorted(native.edges, key=lambda e: e.id),
        sorted(tree.edges, key=lambda e: e.id),
        strict=True,
    ):
        assert a.smc.action.goal_frame == b.smc.action.goal_frame
        assert np.abs(_world_goal(a) - _world_goal(b)).max() < 1e-3
        assert a.smc.action.event == b.smc.action.event


def compile_bag(bag: Path, data: dict[str, Any], tmp_path: Path):
    """The bag's tree; smc inspect shows the bag (its camera, its POI's path), and doctor
    finds it healthy, as compile did (exit 0 both)."""
    from smccli.inspect.recording import inspect
    from smccli.learn.doctor import diagnose, exit_code

    warnings: list[str] = []
    topic_map = parse_topic_map(data)
    tree_path = tmp_path / "tree.json"
    tree = compile_logs([bag], tree_path, topic_map=topic_map, on_warning=warnings.append).tree
    assert not [w for w in warnings if "lack" in w], warnings
    inspect(tree_path, [bag], save=tmp_path / "bag.rrd", topic_map=topic_map, force=True)
    (entities,) = read_rrd(tmp_path / "bag.rrd").values()
    assert {"/world/poi/path", "/world/camera/image"} <= set(entities), sorted(entities)
    diagnosis = diagnose(bag, topic_map)
    assert exit_code([diagnosis]) == 0, [(c.name, c.status, c.detail) for c in diagnosis.checks]
    return tree


# --- storage ------------------------------------------------------------------------------

STORAGE: dict[str, Callable[[Path, list[Message]], Path]] = {
    "rosbag2 sqlite3": lambda d, m: write_rosbag2(d / "bag", m, StoragePlugin.SQLITE3),
    "rosbag2 sqlite3 in 3 files": lambda d, m: write_rosbag2(
        d / "bag", m, StoragePlugin.SQLITE3, 3
    ),
    "rosbag2 MCAP in 2 files": lambda d, m: write_rosbag2(d / "bag", m, StoragePlugin.MCAP, 2),
    "ROS 1 bag": lambda d, m: write_rosbag1(d / "demo.bag", m),
}


@pytest.mark.slow
@pytest.mark.parametrize("shape", list(STORAGE))
def test_each_storage_compiles_into_the_native_tree(
    shape: str, exported, native_tree, tmp_path: Path
) -> None:
    messages, data = exported
    bag = STORAGE[shape](tmp_path, messages)
    same_tree(compile_bag(bag, data, tmp_path), native_tree)


def test_a_split_bag_is_one_demonstration(exported, tmp_path: Path) -> None:
    messages, data = exported
    bag = write_rosbag2(tmp_path / "bag", messages, StoragePlugin.MCAP, 2)
    assert len(list(bag.glob("*.mcap"))) == 2
    log = read_ros2_bag(bag, parse_topic_map(data))
    native = read_ros2_bag_native()
    assert len(log.commands) == len(native.commands)
    assert len(log.frames) == len(native.frames)
    assert [m.t for m in log.marks] == pytest.approx([m.t for m in native.marks], abs=1e-6)


def read_ros2_bag_native():
    from smccli.logs import read_log

    return read_log(NATIVE)


# --- what drivers publish -----------------------------------------------------------------


def _split_joints(messages: list[Message], fingers: set[str]) -> Iterator[Message]:
    """The arm's joints and the gripper's on /joint_states from two publishers, the
    gripper's 3 ms later."""
    for topic, msgtype, t_ns, msg in messages:
        if topic != "/joint_states":
            yield topic, msgtype, t_ns, msg
            continue
        for keep, dt in ((lambda n: n not in fingers, 0), (lambda n: n in fingers, 3_000_000)):
            idx = [i for i, n in enumerate(msg.name) if keep(n)]
            part = TS.types["sensor_msgs/msg/JointState"](
                header=msg.header,
                name=[msg.name[i] for i in idx],
                position=msg.position[idx],
                velocity=msg.velocity[idx] if len(msg.velocity) else msg.velocity,
                effort=msg.effort[idx] if len(msg.effort) else msg.effort,
            )
            yield topic, msgtype, t_ns + dt, part


def _renamed(messages: list[Message]) -> Iterator[Message]:
    for topic, msgtype, t_ns, msg in messages:
        if topic == "/joint_states":
            msg = TS.types[msgtype](
                header=msg.header,
                name=[f"driver_{n}" for n in msg.name],
                position=msg.position,
                velocity=msg.velocity,
                effort=msg.effort,
            )
        yield topic, msgtype, t_ns, msg


def _joy_marks(messages: list[Message]) -> Iterator[Message]:
    """Each mark a press of button 2 on a joystick publishing at 50 Hz."""
    marks = [t for topic, _, t, _ in messages if topic == "/saliency"]
    t0, t1 = messages[0][2], messages[-1][2]
    joy = TS.types["sensor_msgs/msg/Joy"]
    header = TS.types["std_msgs/msg/Header"]
    stamp = TS.types["builtin_interfaces/msg/Time"]
    for t in range(t0, t1, 20_000_000):
        down = any(0 <= t - m < 100_000_000 for m in marks)
        h = header(stamp=stamp(sec=t // 10**9, nanosec=t % 10**9), frame_id="")
        buttons = np.array([0, 0, int(down), 0], dtype=np.int32)
        yield (
            "/joy",
            "sensor_msgs/msg/Joy",
            t,
            joy(header=h, axes=np.zeros(6, np.float32), buttons=buttons),
        )
    yield from (m for m in messages if m[0] != "/saliency")


def _compressed_depth(messages: list[Message]) -> Iterator[Message]:
    """Depth as image_transport's compressedDepth plugin publishes it: a 12-byte header,
    then the 16UC1 image as PNG."""
    image = TS.types["sensor_msgs/msg/CompressedImage"]
    for topic, msgtype, t_ns, msg in messages:
        if topic == "/camera/depth/image_raw":
            raw = np.frombuffer(bytes(msg.data), dtype="<u2").reshape(msg.height, msg.width)
            ok, png = cv2.imencode(".png", raw)
            assert ok
            data = struct.pack("<iff", -1, 0.0, 0.0) + png.tobytes()
            msg = image(
                header=msg.header,
                format="16UC1; compressedDepth png",
                data=np.frombuffer(data, dtype=np.uint8),
            )
            topic, msgtype = "/camera/depth/image_raw/compressedDepth", image.__msgtype__
        yield topic, msgtype, t_ns, msg


def _poi_as_tf(messages: list[Message]) -> Iterator[Message]:
    """No POI topic: the POI is the frame tool0 in /tf (as a UR driver publishes it), its
    transform from the world at each pose the native log measured."""
    tf = TS.types["tf2_msgs/msg/TFMessage"]
    stamped = TS.types["geometry_msgs/msg/TransformStamped"]
    transform = TS.types["geometry_msgs/msg/Transform"]
    vector = TS.types["geometry_msgs/msg/Vector3"]
    header = TS.types["std_msgs/msg/Header"]
    for topic, msgtype, t_ns, msg in messages:
        if topic != "/robot/poi":
            yield topic, msgtype, t_ns, msg
            continue
        p = msg.pose.position
        tr = stamped(
            header=header(stamp=msg.header.stamp, frame_id=msg.header.frame_id),
            child_frame_id="tool0",
            transform=transform(
                translation=vector(x=p.x, y=p.y, z=p.z), rotation=msg.pose.orientation
            ),
        )
        yield "/tf", "tf2_msgs/msg/TFMessage", t_ns, tf(transforms=[tr])


def _in_time_order(messages: Iterator[Message]) -> list[Message]:
    return sorted(messages, key=lambda m: m[2])


@pytest.mark.slow
@pytest.mark.parametrize(
    "shape", ["two publishers", "renamed joints", "joystick", "compressedDepth", "POI from TF"]
)
def test_what_drivers_publish_compiles_into_the_native_tree(
    shape: str, exported, native_tree, tmp_path: Path
) -> None:
    messages, data = exported
    data = yaml.safe_load(yaml.safe_dump(data))
    if shape == "two publishers":
        robot = read_ros2_bag_native().joint_states[0].names
        fingers = {n for n in robot if "finger" in n}
        assert fingers and len(fingers) < len(robot)
        messages = _in_time_order(_split_joints(messages, fingers))
    elif shape == "renamed joints":
        messages = list(_renamed(messages))
        names = read_ros2_bag_native().joint_states[0].names
        data["joints"] = {f"driver_{n}": n for n in names}
    elif shape == "joystick":
        messages = _in_time_order(_joy_marks(messages))
        data["topics"]["marks"] = {"topic": "/joy", "button": 2}
    elif shape == "compressedDepth":
        messages = list(_compressed_depth(messages))
        data["topics"]["depth"] = "/camera/depth/image_raw/compressedDepth"
    else:
        messages = list(_poi_as_tf(messages))
        data["topics"]["poi"] = {"frame": "tool0"}
    bag = write_rosbag2(tmp_path / "bag", messages, StoragePlugin.SQLITE3)
    same_tree(compile_bag(bag, data, tmp_path), native_tree)


def test_two_publishers_merge_by_joint_name(exported, tmp_path: Path) -> None:
    messages, data = exported
    robot = read_ros2_bag_native().joint_states[0].names
    fingers = {n for n in robot if "finger" in n}
    bag = write_rosbag2(
        tmp_path / "bag", _in_time_order(_split_joints(messages, fingers)), StoragePlugin.MCAP
    )
    log = read_ros2_bag(bag, parse_topic_map(data))
    assert {tuple(sorted(j.names)) for j in log.joint_states} == {tuple(sorted(robot))}


# --- what cannot be read: one line ----------------------------------------------------------


def test_what_cannot_be_read_is_one_line(exported, tmp_path: Path) -> None:
    messages, data = exported
    bag = write_rosbag2(tmp_path / "bag", messages, StoragePlugin.SQLITE3, 2)
    db3 = sorted(bag.glob("*.db3"))[0]
    with pytest.raises(LogError, match=r"one file of a sqlite3 bag: give its directory"):
        read_ros2_bag(db3, parse_topic_map(data))
    mcap = write_rosbag2(tmp_path / "split", messages, StoragePlugin.MCAP, 2)
    with pytest.raises(LogError, match=r"one file of a bag split into 2: give its directory"):
        read_ros2_bag(sorted(mcap.glob("*.mcap"))[0], parse_topic_map(data))
    (bag / "metadata.yaml").unlink()
    with pytest.raises(LogError, match=r"needs its metadata.yaml"):
        read_ros2_bag(bag, parse_topic_map(data))
    rvl = tmp_path / "rvl"
    image = TS.types["sensor_msgs/msg/CompressedImage"]
    messages = [
        (t, m, n, image(header=x.header, format="16UC1; compressedDepth rvl", data=x.data))
        if t == "/camera/depth/image_raw/compressedDepth"
        else (t, m, n, x)
        for t, m, n, x in _compressed_depth(messages)
    ]
    write_rosbag2(rvl, messages, StoragePlugin.MCAP)
    data = yaml.safe_load(yaml.safe_dump(data))
    data["topics"]["depth"] = "/camera/depth/image_raw/compressedDepth"
    (tmp_path / "map.yaml").write_text(yaml.safe_dump(data))
    proc = smc("compile", rvl, "--topics", tmp_path / "map.yaml", "-o", tmp_path / "t.json")
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "RVL is not read" in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr


def _without_camera_tf(messages: list[Message]) -> Iterator[Message]:
    tf = TS.types["tf2_msgs/msg/TFMessage"]
    for topic, msgtype, t_ns, msg in messages:
        if topic == "/tf":
            kept = [tr for tr in msg.transforms if tr.child_frame_id != "camera"]
            if not kept:
                continue
            msg = tf(transforms=kept)
        yield topic, msgtype, t_ns, msg


@pytest.mark.slow
def test_doctor_exits_as_compile_does(exported, tmp_path: Path) -> None:
    """On each shape doctor's exit code is compile's: 0 where compile makes the tree, 2
    where it refuses the bag (each reason one line naming the bag's topic or frame);
    never a traceback."""
    messages, data = exported
    cases = {
        "sqlite3 in 2 files": (
            write_rosbag2(tmp_path / "a", messages, StoragePlugin.SQLITE3, 2),
            0,
        ),
        "ROS 1": (write_rosbag1(tmp_path / "b.bag", messages), 0),
        "no metadata.yaml": (write_rosbag2(tmp_path / "c", messages, StoragePlugin.SQLITE3, 2), 2),
        "driver's joint names": (
            write_rosbag2(tmp_path / "d", list(_renamed(messages)), StoragePlugin.MCAP),
            2,
        ),
        "no camera transform": (
            write_rosbag2(
                tmp_path / "e", list(_without_camera_tf(messages)), StoragePlugin.SQLITE3
            ),
            2,
        ),
    }
    (tmp_path / "c" / "metadata.yaml").unlink()
    (tmp_path / "map.yaml").write_text(yaml.safe_dump(data))
    topics = ("--topics", tmp_path / "map.yaml")
    for shape, (bag, code) in cases.items():
        doctor = smc("doctor", bag, *topics)
        out = tmp_path / f"{bag.stem}.json"
        compiled = smc("compile", bag, *topics, "-o", out)
        assert compiled.returncode == code, (shape, compiled.stderr)
        assert doctor.returncode == code, (shape, doctor.stdout)
        assert "Traceback" not in doctor.stderr + compiled.stderr
        if code == 2:
            assert compiled.stderr.count("error:") == 1, compiled.stderr
        if shape == "driver's joint names":
            assert "/joint_states: joint driver_joint1" in compiled.stderr
            assert "`joints:`" in compiled.stderr
        if shape == "no camera transform":
            assert "lack a transform from frame camera to 'world'" in compiled.stderr
        if code == 0:  # inspect shows it: the camera and the POI's path
            rrd = tmp_path / f"{bag.stem}.rrd"
            shown = smc("inspect", out, bag, *topics, "--save", rrd)
            assert shown.returncode == 0, shown.stderr
            (entities,) = read_rrd(rrd).values()
            assert {"/world/poi/path", "/world/camera/image"} <= set(entities), sorted(entities)


# --- smc topics: the first thing a person with a new bag runs -------------------------------

DRAFTED: dict[str, Callable[[list[Message]], tuple[list[Message], StoragePlugin | None]]] = {
    "rosbag2 sqlite3 in 2 files": lambda m: (m, StoragePlugin.SQLITE3),
    "ROS 1 bag": lambda m: (m, None),
    "two publishers": lambda m: (
        _in_time_order(_split_joints(m, {"finger_left_joint", "finger_right_joint"})),
        StoragePlugin.MCAP,
    ),
    "joystick": lambda m: (_in_time_order(_joy_marks(m)), StoragePlugin.SQLITE3),
    "compressedDepth": lambda m: (list(_compressed_depth(m)), StoragePlugin.MCAP),
    "POI from TF": lambda m: (list(_poi_as_tf(m)), StoragePlugin.SQLITE3),
}


@pytest.mark.slow
def test_the_drafted_map_compiles_each_shape_once_its_scene_is_filled_in(
    exported, native_tree, tmp_path: Path
) -> None:
    from smccli.logs.bag_topics import PLACEHOLDER_SCENE, bag_contents, draft_map_text

    messages, _ = exported
    fingers = {"finger_left_joint", "finger_right_joint"}
    assert fingers < set(read_ros2_bag_native().joint_states[0].names)
    for k, make in enumerate(DRAFTED.values()):  # k names the shape in a failure
        shaped, storage = make(messages)
        folder = tmp_path / f"s{k}"
        folder.mkdir()
        if storage is None:
            bag = write_rosbag1(folder / "demo.bag", shaped)
        else:
            bag = write_rosbag2(folder / "bag", shaped, storage, 2 if k == 0 else 1)
        text = draft_map_text(bag_contents(bag))
        assert f"scene: {PLACEHOLDER_SCENE}" in text
        data = yaml.safe_load(text.replace(f"scene: {PLACEHOLDER_SCENE}", f"scene: {SCENE}"))
        same_tree(compile_bag(bag, data, folder), native_tree)
    # A driver's joint names: with the scene given, the draft matches them to the robot's.
    renamed = write_rosbag2(tmp_path / "renamed", list(_renamed(messages)), StoragePlugin.MCAP)
    text_renamed = draft_map_text(bag_contents(renamed), SCENE)
    data = yaml.safe_load(text_renamed)
    assert data["scene"] == SCENE and data["joints"]["driver_joint1"] == "joint1"
    same_tree(compile_bag(renamed, data, tmp_path), native_tree)
    proc = smc("topics", renamed, "--scene", SCENE, "-o", tmp_path / "renamed.yaml")
    assert proc.returncode == 0 and (tmp_path / "renamed.yaml").read_text() == text_renamed
    # The command writes the same draft, and the table names every topic.
    proc = smc("topics", bag, "-o", tmp_path / "map.yaml")
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "map.yaml").read_text() == text
    assert "/joint_states" in proc.stdout and "tool0" in proc.stdout
    again = smc("topics", bag, "-o", tmp_path / "map.yaml")  # an existing map is kept
    assert again.returncode == 2 and len(again.stderr.strip().splitlines()) == 1


FRANKA_ARM = tuple(f"panda_joint{i}" for i in range(1, 8))
FRANKA_FINGERS = ("panda_finger_joint1", "panda_finger_joint2")


def _franka_bag(folder: Path) -> Path:
    """A Franka's joints as franka_ros publishes them: the arm's on
    /franka_state_controller/joint_states, the gripper's on /franka_gripper/joint_states."""
    state = TS.types["sensor_msgs/msg/JointState"]
    header = TS.types["std_msgs/msg/Header"]
    stamp = TS.types["builtin_interfaces/msg/Time"]
    messages: list[Message] = []
    for k in range(5):
        t = 10**9 + k * 10_000_000
        for topic, names in (
            ("/franka_state_controller/joint_states", FRANKA_ARM),
            ("/franka_gripper/joint_states", FRANKA_FINGERS),
        ):
            msg = state(
                header=header(stamp=stamp(sec=t // 10**9, nanosec=t % 10**9), frame_id=""),
                name=list(names),
                position=np.zeros(len(names)),
                velocity=np.zeros(len(names)),
                effort=np.zeros(len(names)),
            )
            messages.append((topic, "sensor_msgs/msg/JointState", t, msg))
    return write_rosbag2(folder, messages, StoragePlugin.MCAP)


def test_a_driver_joint_is_matched_only_when_exactly_one_fits(tmp_path: Path) -> None:
    """A Franka's gripper on a topic of its own: panda_finger_joint1 and panda_joint1 both
    fit the robot's joint1, so neither is renamed; the draft says so, and what is left."""
    from smccli.logs.bag_topics import bag_contents, draft_map_text

    bag = _franka_bag(tmp_path / "franka")
    text = draft_map_text(bag_contents(bag), "bench_pick_panda")
    data = yaml.safe_load(text)
    assert data["scene"] == "bench_pick_panda"
    assert data["joints"] == {f"panda_joint{i}": f"joint{i}" for i in range(3, 8)}, text
    assert "panda_finger_joint1, panda_joint1 all fit robot joint joint1" in text
    assert "the map reads /franka_state_controller/joint_states only" in text
    assert data["topics"]["joint_states"] == "/franka_state_controller/joint_states"
    # The command's last line says what is left: the joints, not the scene it filled in.
    proc = smc("topics", bag, "--scene", "bench_pick_panda", "-o", tmp_path / "map.yaml")
    assert proc.returncode == 0, proc.stderr
    said = " ".join(proc.stdout.split())
    assert "fill in its scene" not in said
    assert (
        "map the joints panda_finger_joint1, panda_finger_joint2, panda_joint1, panda_joint2 "
        "by hand, check each role" in said
    ), said
    proc = smc("topics", bag, "-o", tmp_path / "unfilled.yaml")
    assert proc.returncode == 0, proc.stderr
    said = " ".join(proc.stdout.split())
    assert "fill in its scene, check each role, then" in said and "map the joints" not in said


def test_two_driver_joints_to_one_robot_joint_are_refused(exported, tmp_path: Path) -> None:
    """A map that sends two driver joints to one robot joint would merge their states
    into one joint: one line naming the map and both driver joints, exit 2; so is a
    driver's name the map gives a joint the driver also publishes."""
    messages, data = exported
    bag = write_rosbag2(tmp_path / "bag", list(_renamed(messages)), StoragePlugin.MCAP)
    names = read_ros2_bag_native().joint_states[0].names
    data = yaml.safe_load(yaml.safe_dump(data))
    data["joints"] = {f"driver_{n}": n for n in names}
    data["joints"]["driver_finger_right_joint"] = "finger_left_joint"
    (tmp_path / "map.yaml").write_text(yaml.safe_dump(data))
    proc = smc("compile", bag, "--topics", tmp_path / "map.yaml", "-o", tmp_path / "t.json")
    assert proc.returncode == 2, proc.stderr
    (line,) = proc.stderr.strip().splitlines()
    assert f"{tmp_path / 'map.yaml'}: joints:" in " ".join(proc.stderr.split())
    assert "driver_finger_left_joint and driver_finger_right_joint" in line, line
    assert not (tmp_path / "t.json").exists()
    # The driver publishes joint1 and joint2; the map renames joint2 to joint1.
    plain = write_rosbag2(tmp_path / "plain", messages, StoragePlugin.MCAP)
    data["joints"] = {"joint2": "joint1"}
    with pytest.raises(LogError, match=r"joints joint1 and joint2 both read as robot joint joint1"):
        read_ros2_bag(plain, parse_topic_map(data))


def _shifted(msg: Any, dt_ns: int) -> Any:
    """``msg`` with every stamp in it ``dt_ns`` later."""
    if getattr(msg, "__msgtype__", "") == "builtin_interfaces/msg/Time":
        t = msg.sec * 10**9 + msg.nanosec + dt_ns
        return type(msg)(sec=t // 10**9, nanosec=t % 10**9)
    if not dataclasses.is_dataclass(msg):
        return msg
    values = {}
    for f in dataclasses.fields(msg):
        if f.name == "__msgtype__":
            continue
        v = getattr(msg, f.name)
        values[f.name] = (
            [_shifted(x, dt_ns) for x in v] if isinstance(v, list) else _shifted(v, dt_ns)
        )
    return type(msg)(**values)


def test_times_a_person_reads_are_seconds_from_the_bags_start(exported, tmp_path: Path) -> None:
    """A bag stamped with the wall clock (seconds since 1970) reads from 0: a tree's
    sources say where in the bag each fragment is."""
    messages, data = exported
    epoch = 1_732_600_000 * 10**9
    late = [(t, m, n + epoch, _shifted(x, epoch)) for t, m, n, x in messages]
    bag = write_rosbag2(tmp_path / "bag", late, StoragePlugin.MCAP)
    log = read_ros2_bag(bag, parse_topic_map(data))
    assert 0 <= log.poi_t[0] < 0.1 and log.frames[0].t < 1.0
    assert [m.t for m in log.marks] == pytest.approx(
        [m.t for m in read_ros2_bag_native().marks], abs=0.05
    )
    tree = compile_bag(bag, data, tmp_path)
    assert all(0 <= s.t0 < s.t1 < 60 for e in tree.edges for s in e.sources)


def test_compressed_depth_32fc1_is_quantised_inverse_depth() -> None:
    """image_transport's 32FC1 compressedDepth: v = a / depth + b as 16-bit PNG, 0 where
    there is no depth; read back as a / (v - b), within the quantisation step."""
    from smccli.logs.ros2_bag import compressed_depth

    a, b = 1000.0, -20.0  # the plugin's defaults for depth_quantization 100, max 10 m
    depth = np.array([[0.0, 0.3, 1.0], [2.5, 7.0, np.nan]], dtype=np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        v = np.where(np.isfinite(depth) & (depth > 0), a / depth + b, 0.0)
    ok, png = cv2.imencode(".png", np.round(v).astype(np.uint16))
    assert ok
    data = struct.pack("<iff", 0, a, b) + png.tobytes()
    got = compressed_depth(data, "32FC1; compressedDepth png", 0.001)
    assert isinstance(got, np.ndarray) and got.dtype == np.float32
    assert got[0, 0] == 0.0 and got[1, 2] == 0.0  # no depth stays none
    step = depth[np.isfinite(depth) & (depth > 0)] ** 2 / a  # one unit of v, in metres
    assert np.all(np.abs(got[depth > 0] - depth[depth > 0]) <= step)
    assert "not a 16-bit PNG" in compressed_depth(
        data[:12] + b"junk", "16UC1; compressedDepth", 1.0
    )
