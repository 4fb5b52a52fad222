"""Name rules shared by every part: ROS names and types, Kafka topics, Zenoh key chunks, host ids.

Pure checks that return the problem with a name (``None`` when it is fine); each part raises its
own error with it, so one rule has one definition wherever the name is read (config, wire, API).
"""

from __future__ import annotations

import re

ROS_SEGMENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
"""One segment of a ROS name (a topic, namespace or node name)."""
ROS_MSG_TYPE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*/msg/[A-Za-z_][A-Za-z0-9_]*")
"""A ROS message type, ``package/msg/Name``."""


def ros_segments_problem(segments: list[str]) -> str | None:
    """What is wrong with the segments of a ROS name, or ``None``."""
    for segment in segments:
        if not segment:
            return "empty path segment ('//' or trailing '/')"
        if not ROS_SEGMENT.fullmatch(segment):
            if segment[0].isdigit():
                return f"segment {segment!r} starts with a digit"
            return f"segment {segment!r} has characters other than [A-Za-z0-9_]"
    return None


def ros_topic_problem(name: str) -> str | None:
    """What is wrong with a fully qualified topic or service name (``/a/b``), or ``None``."""
    if not name.startswith("/"):
        return "not fully qualified (must start with '/')"
    if name == "/":
        return "a topic needs at least one segment"
    return ros_segments_problem(name[1:].split("/"))
