"""Row 27, Kafka's side: a wrong SASL password is one clear error naming the setting, not a retry
storm. A broker of the test's own with a SASL_PLAINTEXT listener (PLAIN); the uplink runs as a
real process against it, once with a wrong password and once with the right one."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

from fleetlink.localstack.artifacts import fetch_all
from fleetlink.localstack.java import KAFKA_MIN_JAVA, find_java
from fleetlink.localstack.kafka import KafkaBroker, KafkaSettings
from fleetlink.localstack.process import free_port
from tests.fault.e2e_processes import Process
from tests.helpers import wait_until

PASSWORD = "right-" + "p" * 20


@pytest.fixture
def sasl_kafka(tmp_path: Path) -> Iterator[KafkaSettings]:
    settings = KafkaSettings(
        port=free_port(),
        controller_port=free_port(),
        data_dir=tmp_path / "kafka",
        sasl_port=free_port(),
        sasl_users=(("uplink", PASSWORD),),
    )
    artifacts = fetch_all()
    broker = KafkaBroker(settings, artifacts.kafka_classpath, find_java(KAFKA_MIN_JAVA, "Apache Kafka 4"))
    broker.start(90)
    try:
        yield settings
    finally:
        broker.stop()


def uplink(tmp_path: Path, settings: KafkaSettings, password: str, name: str) -> Process:
    secret = tmp_path / f"{name}.password"
    secret.write_text(password)
    config = tmp_path / f"{name}.yaml"
    config.write_text(
        yaml.safe_dump(
            {
                "kafka": {
                    "bootstrap_servers": f"127.0.0.1:{settings.sasl_port}",
                    "security_protocol": "SASL_PLAINTEXT",
                    "sasl": {"mechanism": "PLAIN", "username": "uplink", "password_file": str(secret)},
                },
                "registry": {"url": "http://127.0.0.1:9/apis/ccompat/v7"},  # never reached
                "zenoh": {"mode": "peer", "listen": [f"tcp/127.0.0.1:{free_port()}"]},
            }
        )
    )
    return Process(name, ["uplink", "run", "-c", str(config)], tmp_path / f"{name}.log")


def test_row27_a_wrong_sasl_password_is_one_clear_error_and_no_retry_storm(
    sasl_kafka: KafkaSettings, tmp_path: Path
) -> None:
    wrong = uplink(tmp_path, sasl_kafka, "wrong-password", "wrong").start()
    assert wrong.proc is not None
    assert wrong.proc.wait(60) == 1  # refused at start-up, before anything else is opened
    lines = wrong.log.read_text().splitlines()
    errors = [line for line in lines if "refused the login" in line]
    assert len(errors) == 1, lines
    assert "kafka.sasl.password_file" in errors[0]
    assert "user 'uplink'" in errors[0]
    assert "wrong-password" not in wrong.log.read_text()
    failures = [line for line in lines if "uthentication" in line]
    assert len(failures) <= 3, failures  # the one error, and at most a couple of client lines
    assert not any("uplink running" in line for line in lines)

    # the same uplink with the right password gets past the check (and runs)
    right = uplink(tmp_path, sasl_kafka, PASSWORD, "right").start()
    try:
        wait_until(
            lambda: "uplink running" in right.tail(), 60, message="the uplink runs with the right password"
        )
    finally:
        code, _took = right.terminate(15)
    assert code == 0
    assert "refused the login" not in right.log.read_text()
