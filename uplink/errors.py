"""Errors of the uplink."""

from __future__ import annotations

from fleetlink.common.errors import ConfigError, FleetlinkError


class UplinkError(FleetlinkError):
    """Base class of the uplink's errors."""


class UnsafeKafkaSettingError(ConfigError, UplinkError):
    """A Kafka override would weaken delivery guarantees (e.g. ``acks=1``)."""


class ProduceError(UplinkError):
    """Kafka refused or failed to acknowledge a record."""

    def __init__(self, message: str, *, code: str, retriable: bool, fatal: bool = False) -> None:
        super().__init__(message)
        self.code = code
        self.retriable = retriable
        self.fatal = fatal
        """The producer cannot go on (fenced by another with its transactional id, or failed for good)."""


class KafkaCredentialsError(ConfigError, UplinkError):
    """The broker refused the configured credentials (SASL or TLS client certificate)."""
