"""Errors of the repeater; each carries what a log line or a status record needs."""

from __future__ import annotations

from fleetlink.errors import ConfigError, FleetlinkError


class RepeaterError(FleetlinkError):
    """Base class of the repeater's errors."""


class RepeaterConfigError(ConfigError, RepeaterError):
    """The repeater cannot start with this configuration (state dir, type store)."""


class EnvelopeError(RepeaterError):
    """Bytes that are not a valid command envelope, reply or status batch.

    ``data`` keeps (a prefix of) the raw bytes for the log or a dead letter.
    """

    def __init__(self, what: str, reason: str, data: bytes = b"") -> None:
        self.what = what
        self.reason = reason
        self.data = data[:256]
        super().__init__(f"malformed {what}: {reason}")


class ConversionError(RepeaterError):
    """A command's Avro value cannot become a ROS message of its type (CDR)."""

    def __init__(self, command_id: str, ros_type: str, reason: str) -> None:
        self.command_id = command_id
        self.ros_type = ros_type
        self.reason = reason
        super().__init__(f"command {command_id}: cannot convert to {ros_type}: {reason}")


class JournalError(RepeaterError):
    """The state directory cannot be read or written."""

    def __init__(self, path: str, reason: str) -> None:
        self.path = path
        self.reason = reason
        super().__init__(f"repeater state {path}: {reason}")
