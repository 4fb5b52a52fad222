"""NativeJob's two parts: the Gate that keeps a stream's next batch behind records on the Python
producer, and the one ack once both parts are settled (fakes for librdkafka and the registry)."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any, cast

from fleetlink._native import ScannedBatch
from fleetlink.schemas.single_object import fingerprint
from fleetlink.uplink.ingest import BatchJob, IngestStats
from fleetlink.uplink.native_ingest import Failures, NativeIngest, NativeJob, view
from fleetlink.uplink.ordered import Gate
from fleetlink.uplink.policy import Decision
from fleetlink.uplink.schema_ids import SchemaIds, SchemaUnavailableError
from fleetlink.wire import Ack, Batch, Record, decode_batch_head, decode_payload, encode_batch, single_object

SCHEMA = {"type": "record", "name": "N", "fields": [{"name": "n", "type": "long"}]}
FP = fingerprint(SCHEMA)


class FakeNative:
    """``NativeIngest.produce``: the records of ``topics`` are taken, the others handed back."""

    def __init__(self) -> None:
        self.on_done: Callable[[Failures], None] | None = None
        self.produced: list[int] = []

    def produce(
        self,
        scanned: ScannedBatch,
        topics: list[int],
        heads: dict[tuple[int, bytes], bytes],
        on_done: Callable[[Failures], None],
        *,
        min_seq: int = 0,
    ) -> list[int]:
        names = {scanned.topics()[i][0] for i in topics}
        others = []
        for index in range(len(scanned)):
            seq, payload = scanned.record(index)
            if decode_payload(payload, seq).kafka_topic in names:
                self.produced.append(seq)
            else:
                others.append(index)
        self.on_done = on_done
        return others


class FakeIds:
    """The registry answers for every topic but ``unavailable``."""

    def __init__(self, unavailable: str) -> None:
        self.unavailable = unavailable

    def id_for(self, site: str, topic: str, fp: bytes, schemas: object = None) -> int:
        if topic == self.unavailable:
            raise SchemaUnavailableError("registry down")
        return 7


class PartJob:
    """The Python part: run() records the part; the test settles it."""

    parts: list[tuple[Batch, Callable[[Ack], None]]]

    def __init__(self) -> None:
        self.parts = []

    def __call__(self, batch: Batch, *, on_done: Callable[[Ack], None]) -> Any:
        parts = self.parts

        class Run:
            def run(self) -> None:
                parts.append((batch, on_done))

        return Run()


def scanned_batch() -> tuple[Batch, ScannedBatch]:
    records = tuple(
        Record(topic, b"r1", single_object(FP, bytes([seq << 1])), seq=seq)
        for seq, topic in enumerate(["t.a", "t.b", "t.a", "t.b"], start=1)
    )
    data = encode_batch(Batch("site-a", "edge-1", "durable", 1, records, {FP: json.dumps(SCHEMA)}))
    parsed = decode_batch_head(data)
    scanned = ScannedBatch.scan(parsed.body, parsed.groups_at)
    return view(parsed.head, scanned), scanned


def job(
    routes: dict[str, Decision], unavailable: str = ""
) -> tuple[NativeJob, FakeNative, PartJob, list[Ack]]:
    head, scanned = scanned_batch()
    native, part, acks = FakeNative(), PartJob(), list[Ack]()
    return (
        NativeJob(
            head,
            scanned,
            native=cast(NativeIngest, native),
            sink=cast(Any, None),
            schema_ids=cast(SchemaIds, FakeIds(unavailable)),
            routes=routes,
            job=cast(Callable[..., BatchJob], part),
            on_done=acks.append,
            stats=IngestStats(),
        ),
        native,
        part,
        acks,
    )


def is_open(gate: Gate) -> bool:
    return gate.opened  # read anew each time (no narrowing across the settling calls)


def ok(batch: Batch) -> Ack:
    return Ack(batch.edge_id, batch.stream, batch.first_seq, batch.last_seq, "ok")


def test_records_left_to_the_python_producer_for_want_of_a_schema_id_hold_the_stream() -> None:
    native_job, native, part, acks = job({}, unavailable="t.b")
    gate = native_job.run()
    assert native.produced == [1, 3]
    assert gate is not None
    assert not is_open(gate)
    assert native.on_done is not None
    native.on_done([])  # the native part is delivered: the Python part still is not
    assert not is_open(gate)
    assert acks == []
    (batch, settle), *_ = part.parts
    assert [r.seq for r in batch.records] == [2, 4]
    settle(ok(batch))
    assert is_open(gate)
    assert [(a.status, a.first_seq, a.last_seq) for a in acks] == [("ok", 1, 4)]


def test_a_gate_opens_even_when_the_python_part_fails() -> None:
    native_job, native, part, acks = job({}, unavailable="t.b")
    gate = native_job.run()
    assert gate is not None
    (batch, settle), *_ = part.parts
    settle(Ack(batch.edge_id, batch.stream, batch.first_seq, batch.last_seq, "error", detail="registry down"))
    assert is_open(gate)
    assert native.on_done is not None
    native.on_done([])
    assert [(a.status, a.detail) for a in acks] == [("error", "registry down")]


def test_diverted_records_on_the_python_producer_do_not_hold_the_stream() -> None:
    native_job, native, part, _acks = job({"t.b": Decision("refuse", "not this site's")})
    assert native_job.run() is None  # the next batch's t.b records take the same way
    assert native.produced == [1, 3]
    assert len(part.parts) == 1


def test_a_batch_all_native_does_not_hold_the_stream() -> None:
    native_job, native, part, acks = job({})
    assert native_job.run() is None
    assert native.produced == [1, 2, 3, 4]
    assert part.parts == []
    assert native.on_done is not None
    native.on_done([])
    assert [a.status for a in acks] == ["ok"]
