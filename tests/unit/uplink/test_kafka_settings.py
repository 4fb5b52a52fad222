"""Kafka settings: safe defaults pinned, weakening overrides refused, secrets kept secret."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from pydantic import ValidationError

from fleetlink.uplink.errors import UnsafeKafkaSettingError
from fleetlink.uplink.kafka_settings import KafkaSection, redacted


def test_producer_always_runs_acks_all_and_idempotent() -> None:
    settings = KafkaSection(bootstrap_servers="b:9092", producer_overrides={"batch.size": 65536})
    conf = settings.producer_config()
    assert conf["acks"] == "all"
    assert conf["enable.idempotence"] is True
    assert conf["batch.size"] == 65536


def test_durations_are_text_and_reach_librdkafka_in_milliseconds() -> None:
    defaults = KafkaSection(bootstrap_servers="b").producer_config()
    assert (defaults["linger.ms"], defaults["delivery.timeout.ms"]) == (1, 120_000)
    settings = KafkaSection.model_validate(
        {"bootstrap_servers": "b", "linger": "20ms", "delivery_timeout": "3m"}
    )
    conf = settings.producer_config()
    assert (conf["linger.ms"], conf["delivery.timeout.ms"]) == (20, 180_000)
    assert settings.model_dump(mode="json")["delivery_timeout"] == "3m"
    for bad in ({"linger": "11s"}, {"delivery_timeout": "500ms"}, {"linger_ms": 5}):
        with pytest.raises(ValidationError):
            KafkaSection.model_validate({"bootstrap_servers": "b", **bad})


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ({"acks": "1"}, "acks='1' would weaken delivery guarantees"),
        ({"acks": 0}, "acks=0 would weaken"),
        ({"enable.idempotence": False}, "enable.idempotence=False would weaken"),
        ({"bootstrap.servers": "x:1"}, "cannot be overridden: set kafka.bootstrap_servers"),
        ({"sasl.password": "hunter2"}, "cannot be overridden"),
    ],
)
def test_weakening_overrides_are_refused(override: dict[str, Any], message: str) -> None:
    with pytest.raises(ValidationError, match=message):
        KafkaSection(bootstrap_servers="b:9092", producer_overrides=override)


def test_acks_all_spelled_minus_one_is_accepted() -> None:
    settings = KafkaSection(bootstrap_servers="b", producer_overrides={"acks": "-1"})
    assert settings.producer_config()["acks"] == "all"


def test_consumer_never_auto_commits() -> None:
    settings = KafkaSection(bootstrap_servers="b", consumer_overrides={"enable.auto.commit": True})
    assert settings.consumer_config("g")["enable.auto.commit"] is False


def test_sasl_needs_exactly_one_password_source(tmp_path: Path) -> None:
    with pytest.raises(ValidationError, match="exactly one of password"):
        KafkaSection.model_validate(
            {"bootstrap_servers": "b", "security_protocol": "SASL_SSL", "sasl": {"username": "u"}}
        )
    with pytest.raises(ValidationError, match="needs a sasl section"):
        KafkaSection(bootstrap_servers="b", security_protocol="SASL_SSL")


def test_password_sources_never_printed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    secret_file = tmp_path / "pw"
    secret_file.write_text("s3cret-from-file\n")
    monkeypatch.setenv("KAFKA_PW", "s3cret-from-env")
    for sasl, expected in (
        ({"username": "u", "password_file": str(secret_file)}, "s3cret-from-file"),
        ({"username": "u", "password_env": "KAFKA_PW"}, "s3cret-from-env"),
        ({"username": "u", "password": "s3cret-inline"}, "s3cret-inline"),
    ):
        settings = KafkaSection.model_validate(
            {"bootstrap_servers": "b", "security_protocol": "SASL_SSL", "sasl": sasl}
        )
        conf = settings.producer_config()
        assert conf["sasl.password"] == expected
        assert expected not in repr(settings)
        assert expected not in str(redacted(conf))


def test_missing_password_env_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("NOPE_PW", raising=False)
    settings = KafkaSection.model_validate(
        {
            "bootstrap_servers": "b",
            "security_protocol": "SASL_PLAINTEXT",
            "sasl": {"username": "u", "password_env": "NOPE_PW"},
        }
    )
    with pytest.raises(UnsafeKafkaSettingError, match="NOPE_PW is not set"):
        settings.producer_config()
