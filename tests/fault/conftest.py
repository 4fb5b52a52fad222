"""Fixtures of the fault tests."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from fleetlink.localstack.artifacts import fetch_all
from fleetlink.localstack.java import KAFKA_MIN_JAVA, find_java
from fleetlink.localstack.kafka import KafkaBroker, KafkaSettings
from fleetlink.localstack.process import free_port
from tests.fault import e2e_processes
from tests.fault.e2e_processes import PROFILES, WanProfile


@pytest.fixture(params=PROFILES, ids=lambda p: p.name)
def wan_profile(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> WanProfile:
    """Run the test once per WAN profile (one batch of 100 in flight; the edge's defaults)."""
    profile: WanProfile = request.param
    monkeypatch.setattr(e2e_processes, "PROFILE", profile)
    return profile


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
