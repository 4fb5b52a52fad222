"""``KafkaTail``: the newest records of one Kafka topic, followed on a thread (the fleet console).

At start it assigns every partition of the topic at ``keep`` records before its end (no
consumer group, nothing committed: the console only reads), then follows new records and keeps
the newest ``keep`` in memory. The dead-letter browser reads the dead-letter topic through one;
the command panel reads the command status topic through another.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from confluent_kafka import OFFSET_END, Consumer, KafkaError, TopicPartition

from fleetlink.common.worker import Worker

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class TailRecord:
    """One Kafka record as a tail keeps it (``timestamp_ms``: the record's timestamp)."""

    partition: int
    offset: int
    timestamp_ms: int
    key: bytes | None
    value: bytes
    headers: tuple[tuple[str, bytes], ...]

    def header(self, name: str) -> str:
        """The value of header ``name`` as text (the first of that name; empty when absent)."""
        for key, value in self.headers:
            if key == name:
                return value.decode("utf-8", "replace")
        return ""


class KafkaTail(Worker):
    """Follows one topic on a thread and keeps its newest ``keep`` records, each also given to ``on_record``.

    ``error`` says why the topic cannot be read (``None`` while it can).
    """

    def __init__(
        self,
        consumer_config: Mapping[str, Any],
        topic: str,
        *,
        keep: int = 500,
        on_record: Callable[[TailRecord], None] | None = None,
    ) -> None:
        super().__init__(f"kafka-tail-{topic}")
        self.topic = topic
        self.keep = keep
        self._config = {
            **consumer_config,
            "group.id": f"fleetlink-console-tail-{topic}",
            "enable.auto.commit": False,
            "enable.partition.eof": False,
        }
        self._on_record = on_record
        self._records: deque[TailRecord] = deque(maxlen=keep)
        self._lock = threading.Lock()
        self.ready = threading.Event()
        """Set once the partitions are assigned (the tail of the topic is being read)."""
        self.error: str | None = None

    def records(self) -> list[TailRecord]:
        """Newest first."""
        with self._lock:
            return list(self._records)[::-1]

    def find(self, partition: int, offset: int) -> TailRecord | None:
        """The kept record at ``partition`` and ``offset`` (``None``: not among those kept)."""
        with self._lock:
            return next((r for r in self._records if (r.partition, r.offset) == (partition, offset)), None)

    def _assign(self, consumer: Consumer) -> bool:
        meta = consumer.list_topics(self.topic, timeout=5)
        topic = meta.topics.get(self.topic)
        if topic is None or topic.error is not None or not topic.partitions:
            self.error = (
                f"topic {self.topic} not found" if topic is None else str(topic.error or "no partitions")
            )
            return False
        parts = []
        for partition in sorted(topic.partitions):
            low, high = consumer.get_watermark_offsets(TopicPartition(self.topic, partition), timeout=5)
            start = max(low, high - self.keep) if high >= 0 else OFFSET_END
            parts.append(TopicPartition(self.topic, partition, start))
        consumer.assign(parts)
        self.error = None
        self.ready.set()
        return True

    def _run(self) -> None:
        consumer = Consumer(self._config)
        try:
            while not self._stop.is_set() and not self._assign(consumer):
                self._stop.wait(2.0)
            while not self._stop.is_set():
                msg = consumer.poll(0.5)
                if msg is None:
                    continue
                err = msg.error()
                if err is not None:
                    if err.code() != KafkaError._PARTITION_EOF:
                        self.error = str(err)
                    continue
                record = TailRecord(
                    partition=msg.partition(),
                    offset=msg.offset(),
                    timestamp_ms=msg.timestamp()[1],
                    key=msg.key(),
                    value=msg.value() or b"",
                    headers=tuple((k, v or b"") for k, v in (msg.headers() or [])),
                )
                with self._lock:
                    self._records.append(record)
                if self._on_record is not None:
                    try:
                        self._on_record(record)
                    except Exception as exc:  # noqa: BLE001 - one bad record must not end the tail
                        log.warning("tail of %s: a record could not be read: %r", self.topic, exc)
        except Exception as exc:  # noqa: BLE001 - said on the page, logged
            self.error = str(exc)
            log.warning("tail of %s stopped: %r", self.topic, exc)
        finally:
            consumer.close()
