"""A failing consumer poll is reported, not raised: the reading thread goes on."""

from __future__ import annotations

import threading
from typing import Any, cast

from confluent_kafka import Consumer, KafkaError, KafkaException

from fleetlink.uplink.consumer_poll import poll_once


class _Consumer:
    def __init__(self, answers: list[Any]) -> None:
        self.answers = answers

    def poll(self, _timeout: float) -> Any:
        answer = self.answers.pop(0)
        if isinstance(answer, Exception):
            raise answer
        return answer


def test_a_failed_poll_is_reported_and_the_next_one_reads() -> None:
    failure = KafkaException(KafkaError(KafkaError._FATAL, "fenced"))
    consumer = cast(Consumer, _Consumer([failure, "record"]))
    reported: list[KafkaException] = []
    stop = threading.Event()
    stop.set()  # the wait after a failure ends at once
    assert poll_once(consumer, 0.1, stop, reported.append) is None
    assert reported == [failure]
    assert poll_once(consumer, 0.1, stop, reported.append) == "record"
    assert len(reported) == 1
