"""An operator releases a robot: ``fleetlink uplink release-robot`` writes a tombstone, and every
uplink's directory forgets which site held it (real Kafka and registry)."""

from __future__ import annotations

import uuid
from pathlib import Path

import yaml

from fleetlink.cli import main
from fleetlink.schemas.registry import SchemaRegistry
from fleetlink.uplink.commands.decode import CommandDecoder
from fleetlink.uplink.commands.directory import RobotDirectory
from fleetlink.uplink.commands.registrations import RegistrationsReader
from fleetlink.uplink.config import UplinkConfig
from tests.helpers import wait_until
from tests.integration.test_commands_harness import CommandProducer, create_topics, irobot_store


def test_a_released_robot_is_forgotten_and_free_to_move(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    topic = f"robots.{uuid.uuid4().hex[:8]}"
    create_topics(kafka_bootstrap, topic)
    data = {
        "kafka": {"bootstrap_servers": kafka_bootstrap},
        "registry": {"url": schema_registry_url},
        "topics": {"registrations": topic},
    }
    path = tmp_path / "uplink.yaml"
    path.write_text(yaml.safe_dump(data))
    config = UplinkConfig.model_validate(data)
    CommandProducer(kafka_bootstrap, schema_registry_url, irobot_store()).register(topic, "tb4_01", "site-a")
    registry = SchemaRegistry(schema_registry_url)
    registry.start()
    directory = RobotDirectory()
    try:
        with RegistrationsReader(config.kafka, topic, CommandDecoder(registry), directory):
            wait_until(lambda: directory.site_of("tb4_01") == "site-a", 15, message="tb4_01 held by site A")
            assert directory.claim("tb4_01", "site-b", registered=True, now_ms=1) is not None
            assert main(["uplink", "release-robot", "tb4_01", "-c", str(path)]) == 0
            wait_until(lambda: directory.site_of("tb4_01") is None, 15, message="the release read back")
            assert directory.claim("tb4_01", "site-b", registered=True, now_ms=2) is None
    finally:
        registry.stop()
