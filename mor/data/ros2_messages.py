"""Writing ROS 2 messages into a rosbag2 MCAP without ROS: the message definitions (``ros2msg`` text, as rosbag2
stores them) of the types our recordings use, for ``mcap_ros2.writer.Writer``, and builders of their payloads.

Read back with ``mor.data.real.RosBag`` (``mcap_ros2``'s decoder), like any TurtleBot recording.
"""

from __future__ import annotations

import math

_SEPARATOR = "=" * 80 + "\n"


def _msgdef(top: str, *dependencies: tuple[str, str]) -> str:
    return top.strip() + "\n" + "".join(_SEPARATOR + f"MSG: {name}\n" + text.strip() + "\n"
                                        for name, text in dependencies)


_TIME = ("builtin_interfaces/msg/Time", "int32 sec\nuint32 nanosec")
_HEADER = ("std_msgs/msg/Header", "builtin_interfaces/Time stamp\nstring frame_id")
_POINT = ("geometry_msgs/msg/Point", "float64 x\nfloat64 y\nfloat64 z")
_QUATERNION = ("geometry_msgs/msg/Quaternion", "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1")
_POSE = ("geometry_msgs/msg/Pose", "Point position\nQuaternion orientation")
_VECTOR3 = ("geometry_msgs/msg/Vector3", "float64 x\nfloat64 y\nfloat64 z")

#: rosbag2 type name -> its message definition.
MSGDEFS: dict[str, str] = {
    "sensor_msgs/msg/CompressedImage": _msgdef("std_msgs/Header header\nstring format\nuint8[] data", _HEADER, _TIME),
    "sensor_msgs/msg/Image": _msgdef("std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n"
                                     "uint8 is_bigendian\nuint32 step\nuint8[] data", _HEADER, _TIME),
    "geometry_msgs/msg/PoseStamped": _msgdef("std_msgs/Header header\nPose pose", _HEADER, _TIME, _POSE, _POINT,
                                             _QUATERNION),
    "geometry_msgs/msg/Twist": _msgdef("Vector3 linear\nVector3 angular", _VECTOR3),
    "std_msgs/msg/String": _msgdef("string data"),
    "std_msgs/msg/Int32": _msgdef("int32 data"),
}


def stamp(ns: int) -> dict[str, int]:
    """builtin_interfaces/Time of ``ns`` nanoseconds."""
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def yaw_quaternion(yaw: float) -> dict[str, float]:
    """geometry_msgs/Quaternion of a rotation by ``yaw`` radians about +z."""
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def pose_stamped(ns: int, frame_id: str, x: float, y: float, yaw: float = 0.0) -> dict:
    """geometry_msgs/PoseStamped of a planar pose (metres, radians); NaN marks a pose the tracker lost."""
    return {"header": {"stamp": stamp(ns), "frame_id": frame_id},
            "pose": {"position": {"x": x, "y": y, "z": 0.0}, "orientation": yaw_quaternion(yaw)}}


def twist(linear_x: float, angular_z: float) -> dict:
    """geometry_msgs/Twist: forward speed (m/s) and turn rate (rad/s, counter-clockwise)."""
    return {"linear": {"x": linear_x, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": angular_z}}


__all__ = ["MSGDEFS", "pose_stamped", "stamp", "twist", "yaw_quaternion"]
