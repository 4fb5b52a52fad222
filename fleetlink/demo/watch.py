"""Kafka-side observers for the demo: records per topic, robot registrations, commands."""

from __future__ import annotations

import threading
import uuid
from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import httpx
from confluent_kafka import Consumer, ConsumerGroupTopicPartitions, KafkaException, Message
from confluent_kafka.admin import AdminClient
from confluent_kafka.schema_registry import SchemaRegistryClient
from confluent_kafka.schema_registry.avro import AvroDeserializer
from confluent_kafka.schema_registry.error import SchemaRegistryError
from confluent_kafka.serialization import MessageField, SerializationContext

from fleetlink.common.worker import Worker
from fleetlink.schemas.registry import on_a_live_connection

Handler = Callable[[str, bytes | None, dict[str, Any] | None, Message], None]


class TopicWatcher(Worker):
    """Consumes ``topics`` in a thread, skipping records stamped before ``since_ms``;
    decodes Avro values if asked."""

    def __init__(
        self,
        bootstrap: str,
        registry_url: str,
        topics: Sequence[str],
        *,
        decode: bool,
        on_record: Handler,
        since_ms: int = 0,
    ) -> None:
        super().__init__("demo-watch")
        self._conf = {
            "bootstrap.servers": bootstrap,
            "group.id": f"fleetlink-demo-{uuid.uuid4().hex[:8]}",
            "auto.offset.reset": "earliest",
            "enable.auto.commit": False,
            "topic.metadata.refresh.interval.ms": 1000,
        }
        self._topics = list(topics)
        self._deserializer = AvroDeserializer(SchemaRegistryClient({"url": registry_url})) if decode else None
        self._on_record = on_record
        self._since_ms = since_ms
        self.counts: Counter[str] = Counter()
        self.assigned = threading.Event()

    def _run(self) -> None:
        consumer = Consumer(self._conf)
        consumer.subscribe(self._topics, on_assign=lambda _c, _p: self.assigned.set())
        try:
            while not self._stop.is_set():
                msg = consumer.poll(0.2)
                if msg is None or msg.error() or msg.timestamp()[1] < self._since_ms:
                    continue  # records from before this run (a shared Kafka) are not ours
                topic = msg.topic() or ""
                self.counts[topic] += 1
                value = None
                if self._deserializer is not None and msg.value():
                    value = self._decode(self._deserializer, topic, msg.value())
                self._on_record(topic, msg.key(), value, msg)
        finally:
            consumer.close()

    @staticmethod
    def _decode(deserializer: AvroDeserializer, topic: str, raw: bytes | None) -> dict[str, Any] | None:
        """The value decoded, or None when it cannot be (not Avro, or the registry unreachable:
        the record is still counted and handed on)."""
        context = SerializationContext(topic, MessageField.VALUE)
        try:
            value: dict[str, Any] | None = on_a_live_connection(lambda: deserializer(raw, context))
        except (KafkaException, SchemaRegistryError, httpx.HTTPError, OSError, ValueError, TypeError):
            return None
        return value


def app_has_committed(bootstrap: str, group: str, topics: Sequence[str]) -> bool:
    """Whether consumer ``group`` has committed an offset on every partition of ``topics``."""
    admin = AdminClient({"bootstrap.servers": bootstrap, "log_level": 3})  # no info lines on close
    try:
        futures = admin.list_consumer_group_offsets([ConsumerGroupTopicPartitions(group)], request_timeout=5)
        partitions = futures[group].result(timeout=10).topic_partitions or []
    except KafkaException:
        return False
    committed = {tp.topic for tp in partitions if tp.offset >= 0 and tp.error is None}
    return set(topics) <= committed


class LogFollower(Worker):
    """Reads the lines a process appends to its log file, in a thread, and hands each to ``on_line``."""

    def __init__(self, path: Path, on_line: Callable[[str], None], *, every_s: float = 0.1) -> None:
        super().__init__("demo-log-follower", join_s=5)
        self._path = path
        self._on_line = on_line
        self._every_s = every_s

    def _run(self) -> None:
        with self._path.open("rb") as log:
            pending = b""
            while True:
                chunk = log.read()
                pending += chunk
                *lines, pending = pending.split(b"\n")
                for line in lines:
                    self._on_line(line.decode(errors="replace"))
                if not chunk and self._stop.wait(self._every_s):
                    return
