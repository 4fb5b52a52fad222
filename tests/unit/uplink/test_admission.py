"""A batch from site B, checked once and produced: sender, schemas, topics, registrations.

The Kafka sink and the registry are stand-ins (this is the pure routing logic); the real path
runs in tests/fault/test_security_faults.py."""

from __future__ import annotations

import io
import json
from collections.abc import Callable, Sequence
from typing import Any

import fastavro
import pytest

from fleetlink.common.metrics import NullMetrics
from fleetlink.schemas.single_object import fingerprint
from fleetlink.uplink.admission import Admission, Admitted, Refused
from fleetlink.uplink.commands.directory import RobotDirectory
from fleetlink.uplink.diversion import Diversion
from fleetlink.uplink.identity import Source
from fleetlink.uplink.ingest import BatchJob, IngestStats
from fleetlink.uplink.policy import InternalTopics, TopicPolicy
from fleetlink.uplink.producer import Delivery, RawCallback
from fleetlink.uplink.refusals import Refusals
from fleetlink.uplink.registration_records import RegistrationWriter
from fleetlink.uplink.schema_ids import SchemaIds
from fleetlink.wire import Ack, Batch, Record, single_object
from fleetlink.wire.robot_events import EVENT_SCHEMA

B = Source("site-b", "edge-b")
SCHEMA = json.dumps({"type": "record", "name": "X", "fields": [{"name": "x", "type": "long"}]})
FP = fingerprint(SCHEMA)
EVENT_FP = fingerprint(EVENT_SCHEMA)
INTERNAL = InternalTopics("fleetlink.robots", "fleetlink.dead-letter", frozenset({"fleetlink.refused"}))


class Registry:
    def __init__(self) -> None:
        self.subjects: list[str] = []

    def register(self, subject: str, schema: dict[str, Any]) -> int:
        self.subjects.append(subject)
        return len(self.subjects)

    def set_compatibility(self, subject: str, level: str) -> None:
        raise AssertionError("not configured")


class Sink:
    """Takes every record and reports it delivered at once."""

    def __init__(self) -> None:
        self.out: list[tuple[str, bytes | None, bytes, list[tuple[str, bytes]]]] = []

    def produce(
        self,
        topic: str,
        key: bytes | None,
        value: bytes,
        *,
        headers: Sequence[tuple[str, bytes]] = (),
        timestamp_ms: int = 0,
        on_delivery: Callable[[Delivery], None],
    ) -> None:
        self.out.append((topic, key, value, list(headers)))
        on_delivery(Delivery(topic, 0, len(self.out), None, 0.0))

    def produce_raw(
        self,
        topic: str,
        key: bytes | None,
        value: bytes,
        *,
        headers: list[tuple[str, bytes]],
        timestamp_ms: int,
        callback: RawCallback,
    ) -> None:
        self.out.append((topic, key, value, headers))
        callback(None, None)

    def topics(self) -> list[str]:
        return [topic for topic, *_ in self.out]


def data(topic: str = "fleet.x", seq: int = 1, site: bytes = b"site-b") -> Record:
    headers = (("fleetlink.site", site), ("fleetlink.edge", b"edge-b"))
    return Record(topic, b"r1", single_object(FP, b"\x02"), headers, 0, seq)


def registration(robot: str, site: str = "site-b", event: str = "registered", seq: int = 1) -> Record:
    datum = {
        "robot": robot,
        "robot_type": "tb4",
        "site": site,
        "edge_id": "edge-b",
        "event": event,
        "reason": "discovered",
        "timestamp": 5,
    }
    out = io.BytesIO()
    fastavro.schemaless_writer(out, fastavro.parse_schema(dict(EVENT_SCHEMA)), datum)
    return Record("fleetlink.robots", robot.encode(), single_object(EVENT_FP, out.getvalue()), (), 5, seq)


class Uplink:
    def __init__(self) -> None:
        self.registry = Registry()
        self.ids = SchemaIds(self.registry)
        self.admission = Admission(TopicPolicy({}, ["fleet.*"], INTERNAL), self.ids)
        self.directory = RobotDirectory()
        self.sink = Sink()
        self.refusals = Refusals(NullMetrics(), refused_topic="fleetlink.refused", max_value_bytes=10_000)
        self.registrations = RegistrationWriter(
            self.registry, "fleetlink.robots", self.directory, clock=lambda: 7.0
        )

    def run(self, batch: Batch) -> Ack | Refused:
        verdict = self.admission.check(B, batch)
        if isinstance(verdict, Refused):
            return verdict
        assert isinstance(verdict, Admitted)
        acks: list[Ack] = []
        diversion = (
            Diversion(
                B, verdict.routes, sink=self.sink, refusals=self.refusals, registrations=self.registrations
            )
            if verdict.routes
            else None
        )
        BatchJob(
            batch,
            sink=self.sink,
            schema_ids=self.ids,
            dead_letter_topic="fleetlink.dead-letter",
            on_done=acks.append,
            stats=IngestStats(),
            diversion=diversion,
        ).run()
        [ack] = acks
        return ack


def batch(*records: Record, site: str = "site-b", schemas: dict[bytes, str] | None = None) -> Batch:
    numbered = tuple(r._replace(seq=i + 1) for i, r in enumerate(records))
    return Batch(site, "edge-b", "durable", 1, numbered, {FP: SCHEMA} if schemas is None else schemas)


def test_an_honest_batch_goes_out_as_it_came() -> None:
    up = Uplink()
    ack = up.run(batch(data(), data()))
    assert isinstance(ack, Ack)
    assert ack.status == "ok"
    assert not ack.failures
    assert up.sink.topics() == ["fleet.x", "fleet.x"]


def test_batches_that_lie_about_their_sender_or_schemas_are_refused_whole() -> None:
    up = Uplink()
    for bad, reason in (
        (batch(data(), site="site-a"), "identity"),
        (batch(data(site=b"site-a")), "headers"),
        (batch(data(), schemas={FP: SCHEMA.replace('"long"', '"string"')}), "schema"),
    ):
        verdict = up.run(bad)
        assert isinstance(verdict, Refused)
        assert verdict.reason == reason
    assert up.sink.out == []


def test_foreign_and_internal_topics_go_to_the_refused_topic() -> None:
    up = Uplink()
    ack = up.run(
        batch(data(), data("site-a.secret"), data("fleetlink.commands.status"), data("fleetlink.refused"))
    )
    assert isinstance(ack, Ack)
    assert ack.status == "ok"
    assert [(f.seq, f.dead_lettered) for f in ack.failures] == [(2, True), (3, True), (4, True)]
    assert up.sink.topics() == ["fleet.x", "fleetlink.refused", "fleetlink.refused", "fleetlink.refused"]
    _, _, _, headers = up.sink.out[1]
    assert (("fleetlink.site", b"site-b")) in headers
    assert ("fleetlink.dlq.topic", b"site-a.secret") in headers
    assert up.registry.subjects == ["fleet.x-value"]  # nothing registered for a refused topic
    assert up.refusals.records[("site-b/edge-b", "topic")] == 3


def test_registrations_are_written_anew_and_a_held_robot_cannot_be_claimed() -> None:
    up = Uplink()
    up.directory.apply("tb4_01", {"robot": "tb4_01", "site": "site-a", "event": "registered"}, 1)
    ack = up.run(batch(registration("tb4_09"), registration("tb4_01"), registration("tb4_02", site="site-a")))
    assert isinstance(ack, Ack)
    assert ack.status == "ok"
    assert [f.seq for f in ack.failures] == [2, 3]
    assert up.sink.topics() == ["fleetlink.robots", "fleetlink.refused", "fleetlink.refused"]
    _topic, key, value, headers = up.sink.out[0]
    assert key == b"tb4_09"
    assert value[:1] == b"\x00"
    assert ("fleetlink.site", b"site-b") in headers
    assert up.directory.site_of("tb4_09") == "site-b"
    assert up.directory.site_of("tb4_01") == "site-a"
    assert up.refusals.records[("site-b/edge-b", "registration")] == 2


def test_dead_letters_carry_the_sender_the_key_proved() -> None:
    up = Uplink()
    sent = (
        ("fleetlink.dlq.stage", b"decode"),
        ("fleetlink.dlq.reason", b"bad cdr"),
    )
    dl = Record("fleetlink.dead-letter", None, b"raw", sent, 0, 1, True)
    ack = up.run(batch(dl, schemas={}))
    assert isinstance(ack, Ack)
    assert ack.status == "ok"
    assert not ack.failures
    [(topic, _, value, headers)] = up.sink.out
    assert (topic, value) == ("fleetlink.dead-letter", b"raw")
    assert ("fleetlink.site", b"site-b") in headers
    assert ("fleetlink.edge", b"edge-b") in headers


@pytest.mark.parametrize(
    ("headers", "why"),
    [
        ((("fleetlink.dlq.reason", b"bad cdr"),), "no fleetlink.dlq.stage header"),
        ((("fleetlink.dlq.stage", b"x"), ("fleetlink.dlq.reason", b"y"), ("x-forged", b"1")), "'x-forged'"),
        ((("fleetlink.dlq.stage", b"x"), ("fleetlink.dlq.reason", b"y" * 5000)), "5000 bytes"),
    ],
)
def test_a_dead_letter_no_edge_would_write_goes_to_the_refused_topic(
    headers: tuple[tuple[str, bytes], ...], why: str
) -> None:
    up = Uplink()
    ack = up.run(batch(Record("fleetlink.dead-letter", None, b"raw", headers, 0, 1, True), schemas={}))
    assert isinstance(ack, Ack)
    assert ack.status == "ok"
    assert [f.dead_lettered for f in ack.failures] == [True]
    assert why in ack.failures[0].reason
    [(topic, _, _value, _headers)] = up.sink.out
    assert topic == "fleetlink.refused"
