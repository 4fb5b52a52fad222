"""Errors of the repeater; each carries what a log line or a status record needs."""

from __future__ import annotations

from fleetlink.common.errors import ConfigError, FleetlinkError


class RepeaterError(FleetlinkError):
    """Base class of the repeater's errors."""


class RepeaterConfigError(ConfigError, RepeaterError):
    """The repeater cannot start with this configuration (state dir, type store)."""


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
