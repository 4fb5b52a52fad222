"""Kafka client settings: typed, secrets kept secret, safe defaults pinned in code.

``acks=all`` and idempotence are not options: an override that would weaken them is refused
at start-up with the YAML path. Credentials are ``SecretStr`` and may come from a file or an
environment variable, so they never appear in config dumps or logs.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr, field_validator, model_validator

from fleetlink.common.configfile import Section
from fleetlink.common.durations import Seconds
from fleetlink.uplink.errors import UnsafeKafkaSettingError

# What the producer always runs with; none of it can be overridden to something weaker.
PINNED_PRODUCER: dict[str, str | int | float | bool] = {
    "acks": "all",
    "enable.idempotence": True,
    "max.in.flight.requests.per.connection": 5,
}
_SAFE_VALUES = {
    "acks": {"all", "-1"},
    "enable.idempotence": {"true"},
}
_NOT_OVERRIDABLE = {
    "bootstrap.servers": "set kafka.bootstrap_servers instead",
    "sasl.password": "use kafka.sasl.password, password_file or password_env (kept secret)",
    "ssl.key.password": "use kafka.ssl.key_password (kept secret)",
    "transactional.id": "transactions are not supported yet",
}


class SaslSection(Section):
    """SASL credentials; give exactly one of ``password``, ``password_file`` and ``password_env``."""

    mechanism: Literal["PLAIN", "SCRAM-SHA-256", "SCRAM-SHA-512"] = "SCRAM-SHA-512"
    username: str
    password: SecretStr | None = None
    password_file: Path | None = None
    password_env: str | None = None

    @model_validator(mode="after")
    def _one_password_source(self) -> SaslSection:
        given = [x for x in (self.password, self.password_file, self.password_env) if x is not None]
        if len(given) != 1:
            raise ValueError("give exactly one of password, password_file, password_env")
        return self

    def resolve_password(self) -> SecretStr:
        """The password from whichever source is given; ``UnsafeKafkaSettingError`` when the file or
        variable cannot be read."""
        if self.password is not None:
            return self.password
        if self.password_file is not None:
            try:
                return SecretStr(self.password_file.read_text(encoding="utf-8").strip())
            except OSError as exc:
                raise UnsafeKafkaSettingError(
                    f"kafka.sasl.password_file: cannot read {self.password_file}: {exc.strerror}"
                ) from None
        name = self.password_env or ""
        value = os.environ.get(name)
        if value is None:
            raise UnsafeKafkaSettingError(f"kafka.sasl.password_env: environment variable {name} is not set")
        return SecretStr(value)


class SslSection(Section):
    """TLS to the brokers: CA, client certificate and key, and whether to verify the broker's host name."""

    ca_location: Path | None = None
    certificate_location: Path | None = None
    key_location: Path | None = None
    key_password: SecretStr | None = None
    endpoint_identification: Literal["https", "none"] = "https"


class KafkaSection(Section):
    """The ``kafka:`` section of the uplink config."""

    bootstrap_servers: str = Field(min_length=1, examples=["127.0.0.1:9092"])
    security_protocol: Literal["PLAINTEXT", "SSL", "SASL_PLAINTEXT", "SASL_SSL"] = "PLAINTEXT"
    sasl: SaslSection | None = None
    ssl: SslSection | None = None
    client_id: str = "fleetlink-uplink"
    linger: Seconds = Field(default=0.001, ge=0, le=10)
    """How long the producer waits to fill a request (librdkafka's ``linger.ms``). A WAN batch
    reaches the producer whole, within a millisecond: 5 ms added 4-5 ms to p50 and p99 and saved
    no CPU; 0 sent a batch's first records on their own (the uplink 24 % more CPU a record at
    2,000/s) (docs/benchmarks.md)."""
    compression: Literal["none", "lz4", "zstd", "snappy", "gzip"] = "lz4"
    delivery_timeout: Seconds = Field(default=120.0, ge=1)
    """How long the producer tries to deliver a record (librdkafka's ``delivery.timeout.ms``): a batch
    is answered by then at the latest, with ``error`` for the records Kafka has not acknowledged."""
    message_max_bytes: int = Field(default=1_000_000, ge=1_000)
    producer_overrides: dict[str, str | int | float | bool] = {}
    consumer_overrides: dict[str, str | int | float | bool] = {}

    @field_validator("producer_overrides")
    @classmethod
    def _no_weakening(cls, value: dict[str, str | int | float | bool]) -> dict[str, str | int | float | bool]:
        for key, raw in value.items():
            if key in _NOT_OVERRIDABLE:
                raise ValueError(f"{key!r} cannot be overridden: {_NOT_OVERRIDABLE[key]}")
            safe = _SAFE_VALUES.get(key)
            if safe is not None and str(raw).lower() not in safe:
                raise ValueError(
                    f"{key}={raw!r} would weaken delivery guarantees; fleetlink pins "
                    f"{key}={PINNED_PRODUCER[key]!r} (at-least-once from the edge spool needs it)"
                )
        return value

    @model_validator(mode="after")
    def _security_consistent(self) -> KafkaSection:
        if self.security_protocol.startswith("SASL") and self.sasl is None:
            raise ValueError(f"security_protocol {self.security_protocol} needs a sasl section")
        return self

    def common_config(self) -> dict[str, str | int | float | bool]:
        """The librdkafka settings producers and consumers share: brokers, client id, security and
        credentials (in clear: log only :func:`redacted` copies)."""
        conf: dict[str, str | int | float | bool] = {
            "bootstrap.servers": self.bootstrap_servers,
            "security.protocol": self.security_protocol,
            "client.id": self.client_id,
        }
        if self.sasl is not None:
            conf["sasl.mechanism"] = self.sasl.mechanism
            conf["sasl.username"] = self.sasl.username
            conf["sasl.password"] = self.sasl.resolve_password().get_secret_value()
        if self.ssl is not None:
            for key, path in (
                ("ssl.ca.location", self.ssl.ca_location),
                ("ssl.certificate.location", self.ssl.certificate_location),
                ("ssl.key.location", self.ssl.key_location),
            ):
                if path is not None:
                    conf[key] = str(path)
            if self.ssl.key_password is not None:
                conf["ssl.key.password"] = self.ssl.key_password.get_secret_value()
            conf["ssl.endpoint.identification.algorithm"] = self.ssl.endpoint_identification
        return conf

    def max_record_bytes(self) -> int:
        """The largest record the producer takes (``message.max.bytes``, an override included):
        told to every edge in its acknowledgements, so larger records never cross the WAN."""
        return int(self.producer_overrides.get("message.max.bytes", self.message_max_bytes))

    def producer_config(self) -> dict[str, str | int | float | bool]:
        """The librdkafka producer settings: this section's, then ``producer_overrides``, then the pinned
        ``acks=all`` and idempotence."""
        conf = self.common_config()
        conf.update(
            {
                "linger.ms": round(self.linger * 1000),
                "compression.type": self.compression,
                "delivery.timeout.ms": round(self.delivery_timeout * 1000),
                "message.max.bytes": self.message_max_bytes,
            }
        )
        conf.update(self.producer_overrides)
        conf.update(PINNED_PRODUCER)
        return conf

    def consumer_config(self, group_id: str) -> dict[str, str | int | float | bool]:
        """The librdkafka consumer settings for ``group_id``: read committed, from the earliest offset,
        never auto-committing."""
        conf = self.common_config()
        conf.update(
            {
                "group.id": group_id,
                "enable.auto.commit": False,
                "auto.offset.reset": "earliest",
                "isolation.level": "read_committed",
            }
        )
        conf.update(self.consumer_overrides)
        conf["enable.auto.commit"] = False  # offsets are committed only after the site acknowledged
        return conf


def redacted(conf: dict[str, str | int | float | bool]) -> dict[str, str | int | float | bool]:
    """A copy safe to log: every password-like value replaced."""
    return {k: ("***" if "password" in k or "secret" in k else v) for k, v in conf.items()}
