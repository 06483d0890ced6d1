"""ROS 2 bags in: every sample log exported to a ROS 2 bag and compiled back through a topic
map gives the tree the native log gives; a bag shaped like a real robot's (a chain of
frames in /tf_static, raw images, poses in the robot's base frame) reads into the same
world; bad maps and bags get one line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import SAMPLE_LOGS, smc
from mcap_ros2.writer import Writer
from scipy.spatial.transform import Rotation

from smccli.errors import LogError, SceneError
from smccli.learn.compile import compile_logs
from smccli.learn.frames import goal_at_scan_pose
from smccli.learn.tree import ROOT, Tree, load_tree
from smccli.logs import read_log
from smccli.logs.ros2_bag import TopicMap, load_topic_map, parse_topic_map, read_ros2_bag
from smccli.logs.ros2_export import export_ros2
from smccli.logs.ros2_msgs import export_map, msgdef

SCENES = ["bench_pick", "bench_pick_panda", "pick_place", "weigh_sort", "rooms"]


def bag_map(scene: str, bag: Path) -> TopicMap:
    """The topic map of an exported bag (as ``smc export`` writes it beside the bag)."""
    from mcap.reader import make_reader

    with bag.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return parse_topic_map(export_map(scene, (c.topic for c in summary.channels.values())))


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> dict[str, list[Path]]:
    root = tmp_path_factory.mktemp("bags")
    out: dict[str, list[Path]] = {}
    for scene in SCENES:
        for log in sorted((SAMPLE_LOGS / scene).glob("*.mcap")):
            bag = root / f"{scene}_{log.stem}.mcap"
            export_ros2(log, bag)
            out.setdefault(scene, []).append(bag)
    return out


def _chain(tree: Tree) -> list[tuple[str, str, int]]:
    return sorted((e.parent, e.child, e.support) for e in tree.edges)


def _world_goal(edge) -> np.ndarray:
    a, p = edge.smc.action, edge.smc.perception
    if a.goal_frame == "scan":
        x, y, yaw = goal_at_scan_pose(a.goal[[0, 1, 3]], p.scan_pose)
        return np.array([x, y, 0.0, yaw])
    return np.asarray(a.goal)


@pytest.mark.slow
@pytest.mark.parametrize("scene", SCENES)
def test_bag_compiles_into_the_native_tree(scene: str, bags, tmp_path: Path) -> None:
    logs = sorted((SAMPLE_LOGS / scene).glob("*.mcap"))
    native = compile_logs(logs, tmp_path / "native.json").tree
    warnings: list[str] = []
    from_bag = compile_logs(
        bags[scene],
        tmp_path / "bag.json",
        topic_map=bag_map(scene, bags[scene][0]),
        on_warning=warnings.append,
    ).tree
    assert _chain(from_bag) == _chain(native)
    assert not [w for w in warnings if "lack" in w]  # every image found its depth and pose
    pairs = zip(
        sorted(native.edges, key=lambda e: e.id),
        sorted(from_bag.edges, key=lambda e: e.id),
        strict=True,
    )
    for a, b in pairs:
        assert a.smc.action.goal_frame == b.smc.action.goal_frame
        assert np.abs(_world_goal(a) - _world_goal(b)).max() < 1e-3  # goals within 1 mm
        assert a.smc.action.event == b.smc.action.event
        pa, pb = a.smc.perception, b.smc.perception
        if pa.cluster is not None:
            assert pb.cluster is not None
            assert np.allclose(pa.cluster.centroid, pb.cluster.centroid, atol=1e-6)
            assert np.allclose(pa.cluster.histogram, pb.cluster.histogram, atol=1e-9)
        assert (pa.weight is None) == (pb.weight is None)
        if pa.weight is not None:
            assert pa.weight == pytest.approx(pb.weight, abs=1e-9)
        if pa.room is not None:
            assert np.allclose(pa.room, pb.room, atol=1e-9)
            assert np.allclose(pa.scan.ranges, pb.scan.ranges, rtol=1e-6)  # float32 in CDR


def test_bag_reads_like_the_native_log(bags) -> None:
    native = read_log(SAMPLE_LOGS / "weigh_sort" / "demo_heavy.mcap")
    bag = read_ros2_bag(bags["weigh_sort"][0], bag_map("weigh_sort", bags["weigh_sort"][0]))
    assert len(bag.frames) == len(native.frames) > 50
    assert np.array_equal(bag.frames[3].depth, native.frames[3].depth)
    assert np.array_equal(bag.frames[3].rgb, native.frames[3].rgb)
    assert np.allclose(bag.frames[3].T_world_camera, native.frames[3].T_world_camera, atol=1e-12)
    assert [c.gripper for c in bag.commands] == [c.gripper for c in native.commands]
    assert np.allclose([c.target for c in bag.commands], [c.target for c in native.commands])
    assert np.array_equal(bag.weight, native.weight)
    assert [(m.t, m.label) for m in bag.marks] == [(m.t, m.label) for m in native.marks]
    # The clouds (PointCloud2, in the world frame here), colours unpacked from PCL's rgb.
    assert len(bag.point_clouds) == len(native.point_clouds) > 0
    a, b = bag.point_clouds[0], native.point_clouds[0]
    assert np.array_equal(a.points, b.points) and np.array_equal(a.colors, b.colors)


# --- a bag shaped like a real robot's ------------------------------------------------------


def _ros_time(t: float) -> dict:
    ns = round(t * 1e9)
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _tf(parent: str, child: str, T: np.ndarray, t: float) -> dict:
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    return {
        "header": {"stamp": _ros_time(t), "frame_id": parent},
        "child_frame_id": child,
        "transform": {
            "translation": dict(zip("xyz", T[:3, 3].tolist(), strict=True)),
            "rotation": {"x": x, "y": y, "z": z, "w": w},
        },
    }


def _robot_like_bag(path: Path, n_frames: int = 3) -> tuple[Path, object]:
    """The first frames of bench_pick's demo as a real robot would record them: raw rgb8 and
    32FC1 images in an optical frame hung off base_link -> camera_link (/tf_static), the POI
    as a PoseStamped in base_link, an Empty message as the mark, no command topics."""
    native = read_log(SAMPLE_LOGS / "bench_pick" / "demo.mcap")
    W_base = np.eye(4)
    W_base[:3, :3] = Rotation.from_euler("z", 0.3).as_matrix()
    W_base[:3, 3] = [0.1, -0.2, 0.05]
    base_W = np.linalg.inv(W_base)
    T_link_optical = np.eye(4)
    T_link_optical[:3, :3] = Rotation.from_euler("xz", [-np.pi / 2, -np.pi / 2]).as_matrix()
    buf = path.open("wb")
    w = Writer(buf)
    s = {
        t: w.register_msgdef(t, msgdef(t))
        for t in (
            "tf2_msgs/msg/TFMessage",
            "sensor_msgs/msg/Image",
            "sensor_msgs/msg/CameraInfo",
            "sensor_msgs/msg/JointState",
            "geometry_msgs/msg/PoseStamped",
            "std_msgs/msg/Empty",
        )
    }
    f0 = native.frames[0]
    T_base_link = base_W @ f0.T_world_camera @ np.linalg.inv(T_link_optical)
    statics = [
        _tf("world", "base_link", W_base, 0.0),
        _tf("base_link", "camera_link", T_base_link, 0.0),
    ]
    statics.append(_tf("camera_link", "camera_color_optical_frame", T_link_optical, 0.0))
    w.write_message("/tf_static", s["tf2_msgs/msg/TFMessage"], {"transforms": statics}, log_time=0)
    for f in native.frames[:n_frames]:
        t_ns = round(f.t * 1e9)
        hdr = {"stamp": _ros_time(f.t), "frame_id": "camera_color_optical_frame"}
        h, wd = f.depth.shape
        rgb = {"header": hdr, "height": h, "width": wd, "encoding": "rgb8", "is_bigendian": 0}
        rgb |= {"step": 3 * wd, "data": f.rgb.tobytes()}
        dep = {"header": hdr, "height": h, "width": wd, "encoding": "32FC1", "is_bigendian": 0}
        dep |= {"step": 4 * wd, "data": f.depth.astype("<f4").tobytes()}
        K = f.K.reshape(-1).tolist()
        info = {"header": hdr, "height": h, "width": wd, "distortion_model": "plumb_bob", "d": []}
        info |= {"k": K, "r": np.eye(3).reshape(-1).tolist(), "p": [0.0] * 12}
        info |= {"binning_x": 0, "binning_y": 0}
        info["roi"] = {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False}
        w.write_message("/cam/image", s["sensor_msgs/msg/Image"], rgb, log_time=t_ns)
        w.write_message("/cam/depth", s["sensor_msgs/msg/Image"], dep, log_time=t_ns)
        w.write_message("/cam/info", s["sensor_msgs/msg/CameraInfo"], info, log_time=t_ns)
    for js in native.joint_states[: 10 * n_frames]:
        msg = {"header": {"stamp": _ros_time(js.t), "frame_id": ""}, "name": list(js.names)}
        msg |= {"position": js.position.tolist(), "velocity": [], "effort": []}
        w.write_message(
            "/joint_states", s["sensor_msgs/msg/JointState"], msg, log_time=round(js.t * 1e9)
        )
    for t, p in zip(native.poi_t[: 10 * n_frames], native.poi[: 10 * n_frames], strict=True):
        T = np.eye(4)
        T[:3, :3] = Rotation.from_euler("z", p[3]).as_matrix()
        T[:3, 3] = p[:3]
        B = base_W @ T
        x, y, z, qw = Rotation.from_matrix(B[:3, :3]).as_quat()
        pose = {"position": dict(zip("xyz", B[:3, 3].tolist(), strict=True))}
        pose["orientation"] = {"x": x, "y": y, "z": z, "w": qw}
        msg = {"header": {"stamp": _ros_time(t), "frame_id": "base_link"}, "pose": pose}
        w.write_message(
            "/tcp_pose", s["geometry_msgs/msg/PoseStamped"], msg, log_time=round(t * 1e9)
        )
    w.write_message("/mark", s["std_msgs/msg/Empty"], {}, log_time=round(native.poi_t[5] * 1e9))
    w.finish()
    buf.close()
    return path, native


ROBOT_MAP = """
scene: bench_pick
topics:
  color: /cam/image
  depth: /cam/depth
  camera_info: /cam/info
  joint_states: /joint_states
  poi: {topic: /tcp_pose}
  marks: /mark
"""


def test_a_real_robots_bag_reads_into_the_world_frame(tmp_path: Path) -> None:
    (tmp_path / "map.yaml").write_text(ROBOT_MAP)
    bag, native = _robot_like_bag(tmp_path / "robot.mcap")
    log = read_ros2_bag(bag, load_topic_map(tmp_path / "map.yaml"))
    assert len(log.frames) == 3
    for got, want in zip(log.frames, native.frames, strict=False):
        assert np.allclose(got.T_world_camera, want.T_world_camera, atol=1e-9)
        assert np.array_equal(got.rgb, want.rgb) and np.array_equal(got.depth, want.depth)
        assert np.allclose(got.K, want.K)
    assert np.allclose(log.poi, native.poi[: len(log.poi)], atol=1e-9)
    # No command topics: the measured POI is the path, the measured opening the gripper.
    assert len(log.commands) == len(log.poi) and log.commands[0].gripper == pytest.approx(
        1.0, abs=0.05
    )
    assert [m.label for m in log.marks] == [""] and log.marks[0].source == "operator"
    assert log.metadata["scene"] == "bench_pick" and "scene.yaml" in log.attachments
    # A bag directory as `ros2 bag record` writes it reads the same.
    folder = tmp_path / "rosbag2_2026_11_22"
    folder.mkdir()
    (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    bag.rename(folder / "rosbag2_2026_11_22_0.mcap")
    again = read_ros2_bag(folder, load_topic_map(tmp_path / "map.yaml"))
    assert len(again.frames) == 3 and again.path.name == "rosbag2_2026_11_22_0.mcap"


# --- bad maps and bags --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.pop("scene"), "missing required key 'scene'"),
        (lambda d: d["topics"].update(colour="/x"), "colour"),
        (lambda d: d["topics"].update(poi="tcp_pose"), "topics.poi"),
        (lambda d: d["topics"].pop("camera_info"), "camera_info"),
        (
            lambda d: d["topics"].update(command=d["topics"]["poi"]),
            "/tcp_pose is both the map's command and its poi",
        ),
    ],
)
def test_bad_maps_are_one_line(tmp_path: Path, edit, message: str) -> None:
    data = yaml.safe_load(ROBOT_MAP)
    edit(data)
    path = tmp_path / "map.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(SceneError) as err:
        load_topic_map(path)
    assert str(err.value).startswith(f"{path}: ") and message in str(err.value)
    assert "\n" not in str(err.value)


def test_bag_missing_a_topic_or_of_another_type_is_one_line(tmp_path: Path) -> None:
    bag, _ = _robot_like_bag(tmp_path / "robot.mcap", n_frames=1)
    data = yaml.safe_load(ROBOT_MAP)
    data["topics"]["weight"] = "/scale"
    with pytest.raises(LogError, match=r"robot.mcap: topic /scale \(the map's weight\) missing"):
        read_ros2_bag(bag, parse_topic_map(data))
    data = yaml.safe_load(ROBOT_MAP)
    data["topics"]["color"] = "/joint_states"
    with pytest.raises(LogError) as err:
        read_ros2_bag(bag, parse_topic_map(data))
    assert "holds sensor_msgs/msg/JointState, expected sensor_msgs/msg/Image or" in str(err.value)
    # A native smc log is no ROS 2 bag.
    with pytest.raises(LogError, match=r"\(protobuf, not ROS 2\), expected"):
        read_ros2_bag(
            SAMPLE_LOGS / "bench_pick" / "demo.mcap",
            parse_topic_map(
                {
                    "scene": "bench_pick",
                    "topics": {
                        "poi": "/robot/poi",
                        "joint_states": "/robot/joint_states",
                        "color": "/camera/color",
                        "camera_info": "/camera/calibration",
                    },
                }
            ),
        )


@pytest.mark.slow
def test_cli_compile_doctor_and_inspect_take_a_map(bags, tmp_path: Path) -> None:
    bag = tmp_path / "demo_ros2.mcap"
    proc = smc("export", SAMPLE_LOGS / "pick_place" / "demo1.mcap", "--ros2", "-o", bag)
    assert proc.returncode == 0, proc.stderr
    m = tmp_path / "demo_ros2.topics.yaml"  # written beside the bag
    assert load_topic_map(m).scene == "pick_place"
    proc = smc("compile", "--topics", m, *bags["pick_place"], "-o", tmp_path / "tree.json")
    assert proc.returncode == 0, proc.stderr
    tree = load_tree(tmp_path / "tree.json")
    assert len(tree.children(ROOT)) == 2  # the two demonstrations branch at the root
    proc = smc("doctor", "--topics", m, bags["pick_place"][0])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "reads as compile reads it" in proc.stdout
    proc = smc(
        "inspect",
        tmp_path / "tree.json",
        bags["pick_place"][0],
        "--topics",
        m,
        "--save",
        tmp_path / "x.rrd",
    )
    assert proc.returncode == 0, proc.stderr
    bad = tmp_path / "bad.yaml"
    bad.write_text("scene: pick_place\ntopics: {poi: nope}\n")
    proc = smc("compile", "--topics", bad, *bags["pick_place"], "-o", tmp_path / "t2.json")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert not (tmp_path / "t2.json").exists()
