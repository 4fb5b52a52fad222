"""Create the topics fleetlink owns with the right settings (registrations are compacted)."""

from __future__ import annotations

import logging

from confluent_kafka import KafkaException
from confluent_kafka.admin import AdminClient, NewTopic

from fleetlink.uplink.config import TopicsSection
from fleetlink.uplink.kafka_settings import KafkaSection

log = logging.getLogger(__name__)


def ensure_topics(kafka: KafkaSection, topics: TopicsSection, timeout_s: float = 15.0) -> None:
    """Create the registrations and marks (compacted), dead-letter, refused and command topics if
    missing.

    A broker that cannot be reached now is not fatal: the uplink starts, records wait in the
    edges' spools, and the next start creates the topics.
    """
    admin = AdminClient(kafka.common_config())
    wanted = [
        NewTopic(
            topics.registrations,
            num_partitions=1,
            replication_factor=-1,
            config={"cleanup.policy": "compact"},
        ),
        NewTopic(topics.dead_letter, num_partitions=1, replication_factor=-1),
        NewTopic(topics.command_dead_letter, num_partitions=1, replication_factor=-1),
        NewTopic(topics.command_status, num_partitions=1, replication_factor=-1),
        NewTopic(topics.refused, num_partitions=1, replication_factor=-1),
        NewTopic(topics.audit, num_partitions=1, replication_factor=-1),
        NewTopic(
            topics.marks,
            num_partitions=1,
            replication_factor=-1,
            config={"cleanup.policy": "compact", "segment.ms": "600000"},
        ),
    ]
    try:
        existing = set(admin.list_topics(timeout=timeout_s).topics)
    except KafkaException as exc:
        log.warning("Kafka not reachable to check fleetlink's topics (%s); will create them later", exc)
        return
    missing = [t for t in wanted if t.topic not in existing]
    if not missing:
        return
    for name, future in admin.create_topics(missing, request_timeout=timeout_s).items():
        try:
            future.result(timeout_s)
            log.info("created topic %s", name)
        except (KafkaException, TimeoutError) as exc:
            if "TOPIC_ALREADY_EXISTS" not in str(exc):
                log.warning("could not create topic %s: %s", name, exc)
