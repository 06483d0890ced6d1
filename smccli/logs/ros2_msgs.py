"""ROS 2 message definitions of the types smc reads from and writes to ROS 2 bags.

A ROS 2 bag in MCAP stores each type's definition as a ``ros2msg`` schema: the type's own
``.msg`` text followed by every type it uses, each after a line of 80 ``=`` and
``MSG: pkg/Type`` (what ``rosbag2`` writes, and what ``mcap-ros2-support`` parses to decode
CDR without a ROS install). The texts below are the ROS 2 (Humble and later) definitions
without their comments.
"""

from __future__ import annotations

from collections.abc import Iterable

_SEP = "=" * 80

_DEFS: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id",
    "std_msgs/String": "string data",
    "std_msgs/Float64": "float64 data",
    "std_msgs/Empty": "",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1",
    "geometry_msgs/Pose": "Point position\nQuaternion orientation",
    "geometry_msgs/PoseStamped": "std_msgs/Header header\nPose pose",
    "geometry_msgs/Transform": "Vector3 translation\nQuaternion rotation",
    "geometry_msgs/TransformStamped": (
        "std_msgs/Header header\nstring child_frame_id\nTransform transform"
    ),
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms",
    "sensor_msgs/Image": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n"
        "uint8 is_bigendian\nuint32 step\nuint8[] data"
    ),
    "sensor_msgs/CompressedImage": "std_msgs/Header header\nstring format\nuint8[] data",
    "sensor_msgs/RegionOfInterest": (
        "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify"
    ),
    "sensor_msgs/CameraInfo": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\n"
        "float64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\n"
        "uint32 binning_y\nRegionOfInterest roi"
    ),
    "sensor_msgs/JointState": (
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
        "float64[] effort"
    ),
    "sensor_msgs/PointField": (
        "uint8 INT8 = 1\nuint8 UINT8 = 2\nuint8 INT16 = 3\nuint8 UINT16 = 4\n"
        "uint8 INT32 = 5\nuint8 UINT32 = 6\nuint8 FLOAT32 = 7\nuint8 FLOAT64 = 8\n"
        "string name\nuint32 offset\nuint8 datatype\nuint32 count"
    ),
    "sensor_msgs/PointCloud2": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nPointField[] fields\n"
        "bool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense"
    ),
    "sensor_msgs/LaserScan": (
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\n"
        "float32 angle_increment\nfloat32 time_increment\nfloat32 scan_time\n"
        "float32 range_min\nfloat32 range_max\nfloat32[] ranges\nfloat32[] intensities"
    ),
}

_BUILTIN = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
}  # fmt: skip


def _deps(name: str) -> list[str]:
    """The message types ``name``'s definition uses, in first-use order, recursively."""
    pkg = name.split("/")[0]
    out: list[str] = []
    for line in _DEFS[name].splitlines():
        kind = line.split()[0].split("[")[0] if line.strip() else ""
        if not kind or kind in _BUILTIN or " = " in line:  # a field of a built-in, a constant
            continue
        full = kind if "/" in kind else f"{pkg}/{kind}"
        for dep in [full, *_deps(full)]:
            if dep not in out:
                out.append(dep)
    return out


def msgdef(datatype: str) -> str:
    """The ``ros2msg`` schema text of ``datatype`` (``sensor_msgs/msg/Image`` or
    ``sensor_msgs/Image``): its definition, then each type it uses."""
    name = datatype.replace("/msg/", "/")
    parts = [_DEFS[name]]
    for dep in _deps(name):
        parts.append(f"{_SEP}\nMSG: {dep}\n{_DEFS[dep]}")
    return "\n".join(parts)


EXPORT_TOPICS: dict[str, tuple[tuple[str, str], ...]] = {
    "/teleop/command": (
        ("/teleop/target", "geometry_msgs/msg/PoseStamped"),
        ("/teleop/gripper", "std_msgs/msg/Float64"),
    ),
    "/robot/joint_states": (("/joint_states", "sensor_msgs/msg/JointState"),),
    "/robot/poi": (("/robot/poi", "geometry_msgs/msg/PoseStamped"),),
    "/camera/color": (("/camera/color/image_raw/compressed", "sensor_msgs/msg/CompressedImage"),),
    "/camera/depth": (("/camera/depth/image_raw", "sensor_msgs/msg/Image"),),
    "/camera/calibration": (("/camera/color/camera_info", "sensor_msgs/msg/CameraInfo"),),
    "/tf": (("/tf", "tf2_msgs/msg/TFMessage"),),
    "/scale/weight": (("/scale/weight", "std_msgs/msg/Float64"),),
    "/saliency": (("/saliency", "std_msgs/msg/String"),),
    "/lidar/scan": (("/scan", "sensor_msgs/msg/LaserScan"),),
    "/lidar/points": (("/lidar/points", "sensor_msgs/msg/PointCloud2"),),
    "/perception/points": (("/perception/points", "sensor_msgs/msg/PointCloud2"),),
}
"""``smc export --ros2``: each native topic -> the ROS 2 topics and types it becomes. The
ground truth (evaluation only) and replay decisions are not exported. Depth is written as
16UC1 in millimetres (the native PNG's values, lossless); colour keeps its JPEG bytes."""

EXPORT_MAP = {
    "world_frame": "world",
    "topics": {
        "command": "/teleop/target",
        "gripper_command": "/teleop/gripper",
        "poi": "/robot/poi",
        "joint_states": "/joint_states",
        "color": "/camera/color/image_raw/compressed",
        "depth": {"topic": "/camera/depth/image_raw", "scale": 0.001},
        "camera_info": "/camera/color/camera_info",
        "weight": "/scale/weight",
        "lidar": "/scan",
        "marks": "/saliency",
        "points": "/perception/points",
    },
}
"""The topic map (``schemas/topic_map.schema.json``, without its ``scene``) that reads an
exported bag back; :func:`export_map` keeps the roles a given bag has."""


def export_map(scene: str, topics_in_bag: Iterable[str]) -> dict[str, object]:
    """The topic map of an exported bag of ``scene`` holding ``topics_in_bag``: the roles of
    :data:`EXPORT_MAP` whose topic the bag has (a bag without a scale has no weight)."""
    have = set(topics_in_bag)
    roles = {
        role: topic
        for role, topic in EXPORT_MAP["topics"].items()  # type: ignore[attr-defined]
        if (topic["topic"] if isinstance(topic, dict) else topic) in have
    }
    return {"scene": scene, "world_frame": EXPORT_MAP["world_frame"], "topics": roles}
