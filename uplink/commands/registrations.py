"""Reads the registrations topic from the beginning, continuously, into a RobotDirectory.

No consumer group: every uplink assigns itself every partition of the compacted topic (it is
small: one record per robot after compaction), reads it from the beginning and follows it;
partitions that appear later (or the topic, if it does not exist yet) are picked up by a
metadata check every few seconds. :meth:`RegistrationsReader.start` waits, bounded, until it
has caught up, so the first commands are routed with what is known.
"""

from __future__ import annotations

import logging
import threading
import time
import uuid
from types import TracebackType
from typing import Any

from confluent_kafka import OFFSET_BEGINNING, Consumer, KafkaError, KafkaException, Message, TopicPartition

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.uplink.commands.decode import CommandDecoder
from fleetlink.uplink.commands.directory import RobotDirectory
from fleetlink.uplink.commands.errors import RegistryUnreachableError, UndecodableValueError
from fleetlink.uplink.consumer_poll import poll_once
from fleetlink.uplink.kafka_settings import KafkaSection

log = logging.getLogger(__name__)

METADATA_EVERY_S = 5.0


class RegistrationsReader:
    """Follows the registrations topic from its beginning on a thread of its own, applying every record to
    ``directory``."""

    def __init__(
        self, kafka: KafkaSection, topic: str, decoder: CommandDecoder, directory: RobotDirectory
    ) -> None:
        self._kafka = kafka
        self._topic = topic
        self._decoder = decoder
        self.directory = directory
        self._consumer: Consumer | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._caught_up = threading.Event()
        self._assigned: list[TopicPartition] = []
        self._limiter = LogLimiter(log)
        self.undecodable = 0

    def start(self, catch_up_s: float = 10.0) -> RegistrationsReader:
        """Assign the topic's partitions from the beginning, start the reading thread, and wait up to
        ``catch_up_s`` seconds for it to reach the end (a warning if not); returns self."""
        conf: dict[str, Any] = dict(self._kafka.common_config())
        conf.update(
            {
                "group.id": f"fleetlink-registrations-{uuid.uuid4().hex[:12]}",  # required; never joined
                "enable.auto.commit": False,
                "auto.offset.reset": "earliest",
                "enable.partition.eof": False,
            }
        )
        self._consumer = Consumer(conf)
        self._assign_new(self._consumer)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="uplink-registrations", daemon=True)
        self._thread.start()
        if not self._caught_up.wait(catch_up_s):
            log.warning(
                "registrations topic %s not read to its end within %.0f s; commands for robots "
                "not known yet go to every site",
                self._topic,
                catch_up_s,
            )
        return self

    def stop(self) -> None:
        """Stop the reading thread (waiting up to 10 s) and close the consumer."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(10)
            self._thread = None
        if self._consumer is not None:
            self._consumer.close()
            self._consumer = None

    def __enter__(self) -> RegistrationsReader:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    @property
    def caught_up(self) -> bool:
        """Whether the reader has reached the end of every partition once since it started."""
        return self._caught_up.is_set()

    def _assign_new(self, consumer: Consumer) -> None:
        """Assign (from the beginning) the topic's partitions not assigned yet."""
        try:
            meta = consumer.list_topics(self._topic, timeout=5.0).topics.get(self._topic)
        except KafkaException as exc:
            self._limiter.log(
                logging.WARNING, "metadata", "registrations: no metadata for %s: %s", self._topic, exc
            )
            return
        if meta is None or meta.error is not None:
            return
        known = {tp.partition for tp in self._assigned}
        new = [
            TopicPartition(self._topic, p, OFFSET_BEGINNING)
            for p in sorted(meta.partitions)
            if p not in known
        ]
        if new:
            consumer.incremental_assign(new)
            self._assigned += new

    def _failed(self, exc: KafkaException) -> None:
        self._limiter.log(logging.WARNING, "poll", "registrations consumer: %s", exc)

    def _run(self) -> None:
        consumer = self._consumer
        if consumer is None:
            return
        last_check = last_metadata = time.monotonic()
        while not self._stop.is_set():
            msg = poll_once(consumer, 0.2, self._stop, self._failed)
            if msg is not None:
                self._handle(msg)
            if time.monotonic() - last_metadata > METADATA_EVERY_S:
                last_metadata = time.monotonic()
                self._assign_new(consumer)
            if not self._caught_up.is_set() and time.monotonic() - last_check > 0.2:
                last_check = time.monotonic()
                if self._at_end(consumer):
                    self._caught_up.set()
                    log.info(
                        "registrations read: %d robots at %d sites",
                        len(self.directory),
                        len(self.directory.sites()),
                    )

    def _at_end(self, consumer: Consumer) -> bool:
        if not self._assigned:
            return False
        try:
            positions = consumer.position([TopicPartition(tp.topic, tp.partition) for tp in self._assigned])
            for tp in positions:
                low, high = consumer.get_watermark_offsets(tp, timeout=1.0, cached=False)
                if high > low and (tp.offset < 0 or tp.offset < high):
                    return False
        except KafkaException:
            return False
        return True

    def _handle(self, msg: Message) -> None:
        err = msg.error()
        if err is not None:
            if err.code() != KafkaError._PARTITION_EOF:
                self._limiter.log(logging.WARNING, "consume", "registrations: %s", err.str())
            return
        raw_key = msg.key()
        key = raw_key.decode("utf-8", "replace") if isinstance(raw_key, bytes) else None
        value = msg.value()
        if value is None:
            self.directory.apply(key, None)
            return
        delay = 0.2
        while not self._stop.is_set():
            try:
                decoded = self._decoder.decode(value)
            except RegistryUnreachableError as exc:
                self._limiter.log(logging.WARNING, "registry", "registrations: %s; retrying", exc)
                self._stop.wait(delay)
                delay = min(delay * 2, 5.0)
                continue
            except UndecodableValueError as exc:
                self.undecodable += 1
                self._limiter.log(
                    logging.WARNING,
                    "undecodable",
                    "registrations: skipping %s[%d]@%d: %s",
                    msg.topic(),
                    msg.partition(),
                    msg.offset(),
                    exc.reason,
                )
                return
            ts_type, timestamp_ms = msg.timestamp()
            if not self.directory.apply(key, decoded.record, timestamp_ms if ts_type else 0):
                self._limiter.log(
                    logging.WARNING,
                    "unusable",
                    "registrations: record %s[%d]@%d has no robot/site/event, or comes from a site "
                    "that does not hold the robot",
                    msg.topic(),
                    msg.partition(),
                    msg.offset(),
                )
            return
