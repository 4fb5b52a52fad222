"""Avro schemas and decoded values shaped like the ones the schemas package generates for ROS
types (records ``ros.<pkg>.msg.<Name>``, each nested type defined on first use and referenced by
full name after, ``ros_type`` on every field), plus small helpers to make samples."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from fleetlink.edge.stages import Sample

TIME = {
    "type": "record",
    "name": "Time",
    "namespace": "ros.builtin_interfaces.msg",
    "fields": [
        {"name": "sec", "type": "int", "ros_type": "int32"},
        {"name": "nanosec", "type": "long", "ros_type": "uint32"},
    ],
}
HEADER = {
    "type": "record",
    "name": "Header",
    "namespace": "ros.std_msgs.msg",
    "fields": [
        {"name": "stamp", "type": TIME, "ros_type": "builtin_interfaces/msg/Time"},
        {"name": "frame_id", "type": "string", "ros_type": "string"},
    ],
}
QUATERNION = {
    "type": "record",
    "name": "Quaternion",
    "namespace": "ros.geometry_msgs.msg",
    "fields": [{"name": n, "type": "double", "ros_type": "float64"} for n in "xyzw"],
}
VECTOR3 = {
    "type": "record",
    "name": "Vector3",
    "namespace": "ros.geometry_msgs.msg",
    "fields": [{"name": n, "type": "double", "ros_type": "float64"} for n in "xyz"],
}


def _array(ros: str) -> dict[str, Any]:
    return {"type": {"type": "array", "items": "double"}, "ros_type": ros}


IMU_SCHEMA: dict[str, Any] = {
    "type": "record",
    "name": "Imu",
    "namespace": "ros.sensor_msgs.msg",
    "ros_type": "sensor_msgs/msg/Imu",
    "fields": [
        {"name": "header", "type": HEADER, "ros_type": "std_msgs/msg/Header"},
        {"name": "orientation", "type": QUATERNION, "ros_type": "geometry_msgs/msg/Quaternion"},
        {"name": "orientation_covariance", **_array("float64[9]")},
        {"name": "angular_velocity", "type": VECTOR3, "ros_type": "geometry_msgs/msg/Vector3"},
        {"name": "angular_velocity_covariance", **_array("float64[9]")},
        # second use of Vector3: a reference by full name, as the generator writes it
        {
            "name": "linear_acceleration",
            "type": "ros.geometry_msgs.msg.Vector3",
            "ros_type": "geometry_msgs/msg/Vector3",
        },
        {"name": "linear_acceleration_covariance", **_array("float64[9]")},
    ],
}

TWIST = {
    "type": "record",
    "name": "Twist",
    "namespace": "ros.geometry_msgs.msg",
    "fields": [
        {"name": "linear", "type": VECTOR3},
        {"name": "angular", "type": "ros.geometry_msgs.msg.Vector3"},
    ],
}
ODOMETRY_SCHEMA: dict[str, Any] = {
    "type": "record",
    "name": "Odometry",
    "namespace": "ros.nav_msgs.msg",
    "fields": [
        {"name": "header", "type": HEADER},
        {"name": "child_frame_id", "type": "string"},
        {
            "name": "pose",
            "type": {
                "type": "record",
                "name": "PoseWithCovariance",
                "namespace": "ros.geometry_msgs.msg",
                "fields": [
                    {
                        "name": "pose",
                        "type": {
                            "type": "record",
                            "name": "Pose",
                            "namespace": "ros.geometry_msgs.msg",
                            "fields": [
                                {
                                    "name": "position",
                                    "type": {
                                        "type": "record",
                                        "name": "Point",
                                        "namespace": "ros.geometry_msgs.msg",
                                        "fields": [{"name": n, "type": "double"} for n in "xyz"],
                                    },
                                },
                                {"name": "orientation", "type": QUATERNION},
                            ],
                        },
                    },
                    {"name": "covariance", "type": {"type": "array", "items": "double"}},
                ],
            },
        },
        {
            "name": "twist",
            "type": {
                "type": "record",
                "name": "TwistWithCovariance",
                "namespace": "ros.geometry_msgs.msg",
                "fields": [
                    {"name": "twist", "type": TWIST},
                    {"name": "covariance", "type": {"type": "array", "items": "double"}},
                ],
            },
        },
    ],
}

# a made-up robot status covering the other kinds (relative names resolve in the namespace)
STATUS_SCHEMA: dict[str, Any] = {
    "type": "record",
    "name": "Status",
    "namespace": "ros.demo_msgs.msg",
    "fields": [
        {"name": "header", "type": HEADER},
        {
            "name": "kidnap",
            "type": {
                "type": "record",
                "name": "KidnapStatus",
                "fields": [{"name": "is_kidnapped", "type": "boolean"}],
            },
        },
        {"name": "last_kidnap", "type": "KidnapStatus"},
        {"name": "mode", "type": "string"},
        {"name": "level", "type": "int"},
        {"name": "battery", "type": "float"},
        {"name": "data", "type": "bytes"},
        {"name": "ranges", "type": {"type": "array", "items": "float"}},
        {"name": "names", "type": {"type": "array", "items": "string"}},
        {"name": "maybe", "type": ["null", "double"]},
    ],
}


def time_of(stamp_ns: int) -> dict[str, int]:
    return {"sec": stamp_ns // 1_000_000_000, "nanosec": stamp_ns % 1_000_000_000}


def imu_value(stamp_ns: int = 0, ax: float = 0.0, wz: float = 0.0) -> dict[str, Any]:
    zero = np.zeros(9)
    return {
        "header": {"stamp": time_of(stamp_ns), "frame_id": "imu_link"},
        "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        "orientation_covariance": zero,
        "angular_velocity": {"x": 0.0, "y": 0.0, "z": wz},
        "angular_velocity_covariance": zero,
        "linear_acceleration": {"x": ax, "y": 0.0, "z": 9.81},
        "linear_acceleration_covariance": zero,
    }


def status_value(**changes: Any) -> dict[str, Any]:
    value: dict[str, Any] = {
        "header": {"stamp": {"sec": 5, "nanosec": 0}, "frame_id": "base"},
        "kidnap": {"is_kidnapped": False},
        "last_kidnap": {"is_kidnapped": True},
        "mode": "dock",
        "level": 3,
        "battery": 0.5,
        "data": b"\x01\x02\x03\x04",
        "ranges": np.array([1.0, 0.5, 2.0], dtype=np.float32),
        "names": ["a", "b"],
        "maybe": None,
    }
    value.update(changes)
    return value


def sample(
    value: Any,
    *,
    robot: str = "tb4_01",
    topic: str = "/tb4_01/x",
    stamp_ns: int = 0,
    raw: bytes | None = None,
) -> Sample:
    return Sample(robot, topic, stamp_ns, value, raw)


def schema(original: dict[str, Any]) -> dict[str, Any]:
    """A private copy, so a test that mutates a schema cannot affect another."""
    return copy.deepcopy(original)
