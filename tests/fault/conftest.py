"""Fixtures of the fault tests."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from fleetlink.localstack.artifacts import fetch_all
from fleetlink.localstack.java import KAFKA_MIN_JAVA, find_java
from fleetlink.localstack.kafka import KafkaBroker, KafkaSettings
from fleetlink.localstack.process import free_port


@pytest.fixture
def own_kafka(tmp_path: Path) -> Iterator[KafkaBroker]:
    """A broker of this test's own, to kill: same data directory across restarts."""
    artifacts = fetch_all()
    broker = KafkaBroker(
        KafkaSettings(port=free_port(), controller_port=free_port(), data_dir=tmp_path / "kafka"),
        artifacts.kafka_classpath,
        find_java(KAFKA_MIN_JAVA, "Apache Kafka 4"),
    )
    broker.start(90)
    try:
        yield broker
    finally:
        broker.stop()
