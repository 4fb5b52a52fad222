"""Records a batch job does not produce as they came: the ``policy`` routes other than ``produce``.

* ``refuse``: the record goes to the refused topic (``refusals``); settled as dead-lettered;
* ``registration``: the uplink writes its own record for an accepted (de)registration
  (``registration_records``), or refuses it like a foreign topic;
* ``dead_letter``: the edge's dead letter, if it is one (its stage and reason, only headers an
  edge writes, each of bounded size: else refused), is written with its value as it is and the
  sender headers set by the uplink (the ones the batch's key proved).

Each record is settled exactly once through ``settle`` (``retry``: the edge sends the batch
again; ``dead``: listed as dead-lettered in the ack; neither: delivered).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

from fleetlink.uplink.dead_letter import DeadLetter, edge_dead_letter_problem, stamped
from fleetlink.uplink.identity import Source
from fleetlink.uplink.policy import Decision
from fleetlink.uplink.producer import Delivery, DeliveryCallback
from fleetlink.uplink.refusals import Refusals
from fleetlink.uplink.registration_records import RegistrationUnavailableError, RegistrationWriter
from fleetlink.wire import Record


class Settle(Protocol):
    """Settles a record of a batch, exactly once."""

    def __call__(self, record: Record, *, retry: str | None = None, dead: str | None = None) -> None:
        """Settle ``record``: ``retry`` has the edge send the batch again, ``dead`` lists it as
        dead-lettered in the ack; neither: delivered."""


class Producer(Protocol):
    """What the diversion needs of the Kafka producer."""

    def produce(
        self,
        topic: str,
        key: bytes | None,
        value: bytes,
        *,
        headers: list[tuple[str, bytes]],
        timestamp_ms: int,
        on_delivery: DeliveryCallback,
    ) -> None:
        """Hand one record to Kafka; ``on_delivery`` hears once how it went."""


class Diversion:
    """The non-``produce`` routes of one batch's topics, for one source."""

    def __init__(
        self,
        source: Source,
        routes: Mapping[str, Decision],
        *,
        sink: Producer,
        refusals: Refusals,
        registrations: RegistrationWriter,
    ) -> None:
        self.source = source
        self.routes = routes
        self._sink = sink
        self._refusals = refusals
        self._registrations = registrations

    def handle(self, record: Record, settle: Settle) -> None:
        """Write ``record`` where its topic's decision routes it (refused topic, registrations, dead
        letters) and settle it once Kafka answers."""
        decision = self.routes[record.kafka_topic]
        if decision.route == "refuse":
            self._refuse(record, "topic", decision.reason, settle)
        elif decision.route == "registration":
            self._registration(record, settle)
        else:
            self._dead_letter(record, settle)

    def _refuse(self, record: Record, reason: str, detail: str, settle: Settle) -> None:
        self._refusals.record(self.source, reason, record.kafka_topic, detail)
        out = self._refusals.refused_record(self.source, record, reason, detail)
        self._produce(out, record, settle, dead=detail)

    def _registration(self, record: Record, settle: Settle) -> None:
        try:
            rebuilt = self._registrations.rebuild(self.source, record)
        except RegistrationUnavailableError as exc:
            settle(record, retry=str(exc))
            return
        if isinstance(rebuilt, str):
            self._refuse(record, "registration", rebuilt, settle)
            return
        out = DeadLetter(
            self._registrations.topic, rebuilt.key, rebuilt.value, rebuilt.headers, rebuilt.timestamp_ms
        )
        self._produce(out, record, settle)

    def _dead_letter(self, record: Record, settle: Settle) -> None:
        source = self.source
        problem = edge_dead_letter_problem(record.headers)
        if problem is not None:
            self._refuse(record, "dead_letter", problem, settle)
            return
        headers = stamped(record.headers, source.site, source.edge_id)
        self._produce(
            DeadLetter(record.kafka_topic, record.key, record.value, headers, record.timestamp_ms),
            record,
            settle,
        )

    def _produce(self, out: DeadLetter, record: Record, settle: Settle, *, dead: str | None = None) -> None:
        """Write ``out`` (a record the uplink made) in place of ``record``; settle it on delivery."""
        topic = out.topic

        def delivered(delivery: Delivery) -> None:
            if delivery.error is None:
                settle(record, dead=dead)
            else:
                settle(record, retry=f"{topic} did not take the record: {delivery.error}")

        try:
            self._sink.produce(
                topic,
                out.key,
                out.value,
                headers=out.headers,
                timestamp_ms=out.timestamp_ms,
                on_delivery=delivered,
            )
        except Exception as exc:  # noqa: BLE001 - keep the batch at the edge
            settle(record, retry=f"{topic} did not take the record: {exc}")
