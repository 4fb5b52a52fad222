"""Errors of the fault-detection app, rooted at fleetlink's FleetlinkError."""

from __future__ import annotations

from typing import Any

from fleetlink.common.errors import ConfigError, FleetlinkError


class FaultDetectionError(FleetlinkError):
    """Base class for everything the fault-detection app raises on purpose."""


class BadRecordError(FaultDetectionError):
    """A sensor record that does not have the shape its ROS type promises.

    Carries the sensor (topic role), the reason and the offending record so that the
    error handler can log it with context; the app skips such records and keeps going.
    """

    def __init__(self, sensor: str, reason: str, record: Any) -> None:
        self.sensor = sensor
        self.reason = reason
        self.record = record
        super().__init__(f"bad {sensor} record: {reason}: {record!r:.200}")


class SettingsError(FaultDetectionError, ConfigError):
    """An option of the app is invalid (window length, topic names, message paths)."""


class CorruptStateError(FaultDetectionError):
    """A value read from the state store is not a robot memory this app wrote."""

    def __init__(self, reason: str, value: Any) -> None:
        self.reason = reason
        self.value = value
        super().__init__(f"corrupt robot memory in the state store: {reason}: {value!r:.200}")
