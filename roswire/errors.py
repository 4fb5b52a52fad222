"""Errors raised by roswire, all rooted at :class:`fleetlink.common.errors.FleetlinkError`.

Each error carries the context a dead-letter record or a log line needs: the offending name,
key expression or raw bytes.
"""

from __future__ import annotations

from fleetlink.common.errors import FleetlinkError


class RoswireError(FleetlinkError):
    """Base class of every roswire error."""


class InvalidNameError(RoswireError):
    """A ROS name (topic, namespace, node, type) breaks the naming rules."""

    def __init__(self, name: str, reason: str) -> None:
        super().__init__(f"invalid ROS name {name!r}: {reason}")
        self.name = name
        self.reason = reason


class KeyParseError(RoswireError):
    """A Zenoh key expression is not an rmw_zenoh data key."""

    def __init__(self, key: str, reason: str) -> None:
        super().__init__(f"not an rmw_zenoh data key {key!r}: {reason}")
        self.key = key
        self.reason = reason


class QosParseError(RoswireError):
    """A compact QoS string (the last chunk of an endpoint token) is malformed."""

    def __init__(self, text: str, reason: str) -> None:
        super().__init__(f"malformed QoS string {text!r}: {reason}")
        self.text = text
        self.reason = reason


class TokenError(RoswireError):
    """A liveliness token key does not follow rmw_zenoh's grammar."""

    def __init__(self, key: str, reason: str) -> None:
        super().__init__(f"malformed liveliness token {key!r}: {reason}")
        self.key = key
        self.reason = reason


class AttachmentError(RoswireError):
    """A per-sample attachment is neither the 33-byte (v2) nor the 77-byte (v1) layout.

    ``raw`` is the attachment; a subscriber also sets ``key`` and ``payload`` (the sample's data
    key and bytes), so the whole sample can be dead-lettered.
    """

    def __init__(self, raw: bytes, reason: str, *, key: str = "", payload: bytes = b"") -> None:
        where = f" on {key!r}" if key else ""
        super().__init__(f"broken rmw_zenoh attachment{where} ({len(raw)} bytes {raw[:40].hex()}): {reason}")
        self.raw = raw
        self.reason = reason
        self.key = key
        self.payload = payload


class PayloadError(RoswireError):
    """A sample payload is not a CDR-encoded message of the expected type."""

    def __init__(self, key: str, typename: str | None, raw: bytes, reason: str) -> None:
        super().__init__(
            f"bad payload on {key!r} (type {typename or '?'}, {len(raw)} bytes {raw[:16].hex()}): {reason}"
        )
        self.key = key
        self.typename = typename
        self.raw = raw
        self.reason = reason


class RobotError(RoswireError):
    """A robot registration request is invalid (unknown robot type, bad name)."""


class BagError(RoswireError):
    """A rosbag2 recording cannot be opened or replayed."""
