"""Before the uplink opens anything else: does the broker accept its credentials?

A wrong SASL password (or a TLS client certificate the broker refuses) would otherwise show as
librdkafka reconnecting and failing again, one warning after another, while every batch is
answered ``error``. Here it is one ``KafkaCredentialsError`` at start-up, naming the setting
to fix; the process exits without a retry loop. A broker that cannot be reached at all is not
an error here: the uplink starts and the edges keep their records until Kafka is back.
"""

from __future__ import annotations

import time
from typing import Any

from confluent_kafka import KafkaError, KafkaException
from confluent_kafka.admin import AdminClient

from fleetlink.uplink.errors import KafkaCredentialsError
from fleetlink.uplink.kafka_settings import KafkaSection

_AUTH_CODES = frozenset(
    code
    for code in (
        getattr(KafkaError, "_AUTHENTICATION", None),
        getattr(KafkaError, "SASL_AUTHENTICATION_FAILED", None),
        getattr(KafkaError, "_SSL", None),
    )
    if code is not None
)


def credentials_setting(kafka: KafkaSection) -> str:
    """The YAML path an operator must look at when the broker refuses the login."""
    sasl = kafka.sasl
    if sasl is not None:
        source = (
            "password"
            if sasl.password is not None
            else "password_file"
            if sasl.password_file is not None
            else "password_env"
        )
        return f"kafka.sasl.{source} (user {sasl.username!r}, mechanism {sasl.mechanism})"
    return "kafka.ssl (client certificate and key)"


def check_kafka_access(kafka: KafkaSection, timeout_s: float = 10.0) -> None:
    """Raise ``KafkaCredentialsError`` when the broker refuses the login (one attempt, bounded)."""
    if kafka.sasl is None and kafka.ssl is None:
        return
    refused: list[KafkaError] = []

    def on_error(err: KafkaError) -> None:
        if err.code() in _AUTH_CODES:
            refused.append(err)

    conf: dict[str, Any] = dict(kafka.common_config())
    conf["error_cb"] = on_error
    # one failed login is enough to know: do not let the client hammer the broker meanwhile
    conf["reconnect.backoff.ms"] = 1000
    conf["reconnect.backoff.max.ms"] = 10_000
    admin = AdminClient(conf)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not refused:
        try:
            admin.list_topics(timeout=0.5)
            return
        except KafkaException as exc:
            err = exc.args[0] if exc.args and isinstance(exc.args[0], KafkaError) else None
            if err is not None and err.code() in _AUTH_CODES:
                refused.append(err)
        admin.poll(0.1)
    if refused:
        raise KafkaCredentialsError(
            f"Kafka {kafka.bootstrap_servers} refused the login: {refused[0].str()}; check "
            f"{credentials_setting(kafka)}"
        )
