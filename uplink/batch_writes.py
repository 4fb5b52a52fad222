"""Writing a repeater's batch (command status events, call outcomes) to Kafka and answering its
query once Kafka has every record of it."""

from __future__ import annotations

import threading
from collections.abc import Callable

import zenoh

from fleetlink.uplink.errors import ProduceError
from fleetlink.uplink.producer import Delivery
from fleetlink.wire.commands import StatusAck, encode_status_ack

Done = Callable[[str | None], None]
"""Called once with None when every record is in Kafka, else with the first problem."""


class DeliveryTally:
    """Counts the delivery reports of ``count`` records and calls ``done`` after the last one."""

    def __init__(self, count: int, done: Done, on_written: Callable[[], None]) -> None:
        self._left = count
        self._done = done
        self._on_written = on_written
        self._problems: list[str] = []
        self._lock = threading.Lock()

    def delivered(self, report: Delivery) -> None:
        """Count one delivery report; after the last, call ``done`` with None or the first error."""
        with self._lock:
            if report.error is not None:
                self._problems.append(str(report.error))
            else:
                self._on_written()
            self._left -= 1
            finished = self._left == 0
        if finished:
            self._done(self._problems[0] if self._problems else None)

    def failed(self, topic: str, exc: Exception) -> None:
        """A record the producer refused to take: it counts as delivered with an error."""
        failure = ProduceError(f"produce failed: {exc}", code="_PRODUCE", retriable=True)
        self.delivered(Delivery(topic, -1, -1, failure, 0.0))


def wait_written(write: Callable[[Done], None], timeout: float, what: str) -> str | None:
    """Run ``write`` and wait for its ``done``: None when Kafka has every record, else the problem."""
    finished = threading.Event()
    outcome: list[str | None] = []

    def done(problem: str | None) -> None:
        outcome.append(problem)
        finished.set()

    write(done)
    if not finished.wait(timeout):
        return f"Kafka did not acknowledge the {what} records in time"
    return outcome[0]


def refuse(query: zenoh.Query, reason: str) -> None:
    """Answer ``query`` with an error and let it go."""
    query.reply_err(reason.encode())
    query.drop()


def ack_when_written(query: zenoh.Query, count: int, on_problem: Callable[[str], object]) -> Done:
    """A ``done`` that answers ``query`` with a :class:`StatusAck`: ``count`` records accepted, or
    none and the problem (which ``on_problem`` hears first)."""

    def done(problem: str | None) -> None:
        try:
            ack = StatusAck(count) if problem is None else StatusAck(0, problem[:500])
            if problem is not None:
                on_problem(problem)
            query.reply(query.key_expr, encode_status_ack(ack))
        finally:
            query.drop()

    return done
