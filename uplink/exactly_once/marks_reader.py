"""The marks topic read from its start and followed: every exactly-once stream's last mark.

Read with ``isolation.level=read_committed``: a mark of an aborted transaction never counts.
``catch_up`` answers once everything committed up to a moment has been read, which a producer
that has just fenced a stream's previous owner needs before it trusts the stream's mark.
"""

from __future__ import annotations

import logging
import threading
import time

from confluent_kafka import OFFSET_BEGINNING, Consumer, KafkaError, KafkaException, TopicPartition

from fleetlink.common.worker import Worker
from fleetlink.uplink.consumer_poll import poll_once
from fleetlink.uplink.exactly_once.marks import NO_MARK, Mark, MarkKey, decode_mark
from fleetlink.uplink.kafka_settings import KafkaSection

log = logging.getLogger(__name__)

_RETRY_S = 0.1
"""The pause before asking a partition's end again after a retriable error."""


class MarksReader(Worker):
    """A thread following the marks topic (one partition) into a map of stream -> mark."""

    def __init__(self, kafka: KafkaSection, topic: str, group_id: str) -> None:
        super().__init__("uplink-marks")
        conf = kafka.consumer_config(group_id)
        conf["enable.partition.eof"] = True
        self._consumer = Consumer(conf)
        self._partition = TopicPartition(topic, 0)
        self._consumer.assign([TopicPartition(topic, 0, OFFSET_BEGINNING)])
        self._marks: dict[bytes, Mark] = {}
        self._end = -1
        """The offset the reader last reached the end of the partition at (read_committed)."""
        self._cond = threading.Condition()

    def mark(self, key: MarkKey) -> Mark:
        """The last committed mark of ``key`` the reader has seen (``NO_MARK``: none)."""
        with self._cond:
            return self._marks.get(key.kafka_key(), NO_MARK)

    def note(self, key: MarkKey, mark: Mark) -> None:
        """A mark this uplink has just committed (the reader will read it too, later)."""
        with self._cond:
            self._marks[key.kafka_key()] = mark

    def catch_up(self, timeout_s: float) -> bool:
        """Wait until everything committed to the marks topic by now has been read; False when
        that did not happen within ``timeout_s`` (or the end is unknown: Kafka unreachable).
        Learning the end and reading up to it each get ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while True:
            left = max(deadline - time.monotonic(), 0.001)
            try:
                _low, high = self._consumer.get_watermark_offsets(self._partition, left, cached=False)
                break
            except (KafkaException, RuntimeError) as exc:  # unreachable, or the consumer closed
                # a leader being elected (a new topic, a broker restarting) passes: ask again
                again = isinstance(exc, KafkaException) and _transient(exc.args[0])
                if not again or time.monotonic() >= deadline or self._stop.wait(_RETRY_S):
                    log.warning("marks topic %s: cannot learn its end: %s", self._partition.topic, exc)
                    return False
        with self._cond:
            return bool(self._cond.wait_for(lambda: self._end >= high, timeout_s))

    def _failed(self, exc: KafkaException) -> None:
        log.warning("marks topic %s: %s", self._partition.topic, exc)

    def _run(self) -> None:
        consumer = self._consumer
        try:
            while not self._stop.is_set():
                msg = poll_once(consumer, 0.2, self._stop, self._failed)
                if msg is None:
                    continue
                error = msg.error()
                if error is not None:
                    if error.code() == KafkaError._PARTITION_EOF:
                        with self._cond:
                            self._end = max(self._end, msg.offset())
                            self._cond.notify_all()
                    elif error.code() != KafkaError.UNKNOWN_TOPIC_OR_PART:
                        log.warning("marks topic %s: %s", self._partition.topic, error.str())
                    continue
                mark = decode_mark(msg.value() or b"")
                key = msg.key()
                if mark is None or key is None:
                    continue
                with self._cond:
                    known = self._marks.get(key)
                    if known is None or known.origin != mark.origin or mark.seq > known.seq:
                        self._marks[key] = mark
        finally:
            consumer.close()


_LEADERLESS = frozenset(
    (KafkaError.NOT_LEADER_FOR_PARTITION, KafkaError.LEADER_NOT_AVAILABLE, KafkaError.UNKNOWN_TOPIC_OR_PART)
)


def _transient(error: KafkaError) -> bool:
    """An error that passes by itself: a partition between leaders, a topic not yet known."""
    return bool(error.retriable()) or error.code() in _LEADERLESS
