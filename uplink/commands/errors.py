"""Errors of the uplink's command side; each carries the record coordinates it concerns."""

from __future__ import annotations

from fleetlink.uplink.errors import UplinkError


class CommandError(UplinkError):
    """Base class of the command router's errors."""


class UndecodableCommandError(CommandError):
    """A command record that cannot be read: it goes to the command dead-letter topic.

    Carries the record's coordinates and raw bytes so the dead letter has them.
    """

    def __init__(
        self, reason: str, *, topic: str, partition: int, offset: int, key: bytes | None, raw: bytes | None
    ) -> None:
        self.reason = reason
        self.topic = topic
        self.partition = partition
        self.offset = offset
        self.key = key
        self.raw = raw
        super().__init__(f"{topic}[{partition}]@{offset} key={key!r}: {reason}")


class RegistryUnreachableError(CommandError):
    """The schema registry could not answer now: the record is tried again later."""


class RoutingError(CommandError):
    """A decoded command names no usable robot or ROS topic (also dead-lettered)."""


class UndecodableValueError(CommandError):
    """A record value that is not Avro in the Confluent wire format with a known schema."""

    def __init__(self, reason: str, raw: bytes | None) -> None:
        self.reason = reason
        self.raw = raw
        super().__init__(reason)
