"""One poll of a Kafka consumer that a failure does not end: the reading thread goes on."""

from __future__ import annotations

import threading
from collections.abc import Callable

from confluent_kafka import Consumer, KafkaException, Message

FAILED_WAIT_S = 1.0


def poll_once(
    consumer: Consumer, timeout_s: float, stop: threading.Event, report: Callable[[KafkaException], None]
) -> Message | None:
    """``consumer.poll(timeout_s)``; when the consumer raises (a fatal error, a rebalance callback
    that failed), ``report`` it and wait a second (or until ``stop``) instead: None."""
    try:
        return consumer.poll(timeout_s)
    except KafkaException as exc:
        report(exc)
        stop.wait(FAILED_WAIT_S)
        return None
