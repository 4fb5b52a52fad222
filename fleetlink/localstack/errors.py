"""Errors of the local stack: each says what went wrong and what to do."""

from fleetlink.common.errors import FleetlinkError


class StackError(FleetlinkError):
    """The local Kafka / registry could not be fetched, started or reached."""
