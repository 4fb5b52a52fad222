"""The marks reader's catch-up across a partition between leaders (a new topic, a broker restart)."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import pytest
from confluent_kafka import KafkaError, KafkaException, TopicPartition

from fleetlink.uplink.exactly_once.marks_reader import MarksReader
from fleetlink.uplink.kafka_settings import KafkaSection


class _Consumer:
    """Answers each watermark question with the next of ``answers`` (an error raised, or ends)."""

    def __init__(self, answers: list[Exception | tuple[int, int]]) -> None:
        self.answers = answers
        self.asked = 0

    def get_watermark_offsets(self, _tp: TopicPartition, _timeout: float, cached: bool) -> tuple[int, int]:
        answer = self.answers[min(self.asked, len(self.answers) - 1)]
        self.asked += 1
        if isinstance(answer, Exception):
            raise answer
        return answer

    def close(self) -> None:
        pass


@pytest.fixture
def reader() -> Iterator[MarksReader]:
    made = MarksReader(KafkaSection(bootstrap_servers="127.0.0.1:9"), "marks", "g")
    real: Any = made._consumer
    yield made
    real.close()


def _leaderless() -> KafkaException:
    return KafkaException(KafkaError(KafkaError.NOT_LEADER_FOR_PARTITION))


def test_a_partition_between_leaders_is_asked_again_until_its_end_is_known(reader: MarksReader) -> None:
    consumer = _Consumer([_leaderless(), _leaderless(), (0, 5)])
    reader._consumer = consumer
    reader._end = 5
    assert reader.catch_up(5.0)
    assert consumer.asked == 3


def test_an_error_that_does_not_pass_fails_at_once(reader: MarksReader) -> None:
    consumer = _Consumer([KafkaException(KafkaError(KafkaError.TOPIC_AUTHORIZATION_FAILED)), (0, 5)])
    reader._consumer = consumer
    reader._end = 5
    assert not reader.catch_up(5.0)
    assert consumer.asked == 1


def test_a_partition_that_stays_leaderless_fails_within_the_timeout(reader: MarksReader) -> None:
    consumer = _Consumer([_leaderless()])
    reader._consumer = consumer
    started = time.monotonic()
    assert not reader.catch_up(0.3)
    assert time.monotonic() - started < 5.0
    assert consumer.asked >= 2
