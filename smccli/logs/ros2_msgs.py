"""ROS 2 message definitions of the types smc writes to ROS 2 bags, and what it exports.

A ROS 2 bag in MCAP stores each type's definition as a ``ros2msg`` schema: the type's own
``.msg`` text followed by every type it uses, each after a line of 80 ``=`` and
``MSG: pkg/Type`` (what ``rosbag2`` writes, and what ``mcap-ros2-support`` parses to decode
CDR without a ROS install). ``rosbags`` generates these texts from its store of ROS 2
Humble's types.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable
from typing import Any


@functools.cache
def _typestore() -> Any:
    from rosbags.typesys import Stores, get_typestore  # imported on first use

    return get_typestore(Stores.ROS2_HUMBLE)


def msgdef(datatype: str) -> str:
    """The ``ros2msg`` schema text of ``datatype`` (``sensor_msgs/msg/Image`` or
    ``sensor_msgs/Image``): its definition, then each type it uses, as ``rosbags``
    generates it from ROS 2 Humble's definitions."""
    name = datatype if "/msg/" in datatype else datatype.replace("/", "/msg/", 1)
    text, _md5 = _typestore().generate_msgdef(name, ros_version=2)
    return str(text)


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
