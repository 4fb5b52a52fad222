"""A robot's order across a batch that was not produced: the uplink with its registry behind a relay.

An edge has several batches of a stream in flight. When one is not produced (the registry did
not answer, the uplink asks for a schema the batch left out, or it was too busy to read it) and
the next one could be, the next must not reach Kafka before it: the uplink answers it
``held_back`` until the first comes again, then takes both, in order.
"""

from __future__ import annotations

import dataclasses
import json
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit, urlunsplit

import pytest
import zenoh

from fleetlink.localstack.relay import TcpRelay
from fleetlink.schemas.single_object import fingerprint
from fleetlink.uplink.config import UplinkConfig
from fleetlink.uplink.service import Uplink
from fleetlink.wire import Record, decode_ack, ingest_key, single_object
from fleetlink.wire.batch import Batch, encode_batch
from tests.helpers import zenoh_peer_config
from tests.integration.test_uplink_ingest import read_topic, send


@dataclass
class Bed:
    registry: TcpRelay
    edge: zenoh.Session
    topic: str
    schema: dict[str, object]

    def batch(self, first: int, count: int, *, carry_schema: bool = True, stream: str = "") -> Batch:
        topic = stream or self.topic
        schema = {**self.schema, "name": f"{self.schema['name']}{stream.replace('.', '')}"}
        fp = fingerprint(schema)
        records = tuple(
            Record(topic, b"tb4_01", single_object(fp, bytes([seq << 1])), (("n", b"%d" % seq),), seq=seq)
            for seq in range(first, first + count)
        )
        if carry_schema:
            return Batch("site-a", "edge-1", topic, first, records, {fp: json.dumps(schema)})
        return Batch("site-a", "edge-1", topic, first, records, elided=frozenset({fp}))

    def order(self, bootstrap: str, count: int) -> list[int]:
        return [int(dict(m.headers() or [])["n"]) for m in read_topic(bootstrap, self.topic, count)]


@pytest.fixture
def bed(kafka_bootstrap: str, schema_registry_url: str, zenoh_router: str) -> Iterator[Bed]:
    yield from open_bed(kafka_bootstrap, schema_registry_url, zenoh_router)


@pytest.fixture
def one_slot_bed(kafka_bootstrap: str, schema_registry_url: str, zenoh_router: str) -> Iterator[Bed]:
    """An uplink that reads one batch at a time and answers the others ``busy``."""
    yield from open_bed(kafka_bootstrap, schema_registry_url, zenoh_router, max_concurrent_batches=1)


@pytest.fixture
def two_slot_bed(kafka_bootstrap: str, schema_registry_url: str, zenoh_router: str) -> Iterator[Bed]:
    """An uplink that takes two batches at a time and answers the others ``busy``."""
    yield from open_bed(kafka_bootstrap, schema_registry_url, zenoh_router, max_concurrent_batches=2)


def open_bed(
    kafka_bootstrap: str, schema_registry_url: str, zenoh_router: str, **ingest: Any
) -> Iterator[Bed]:
    url = urlsplit(schema_registry_url)
    assert url.port is not None
    name = uuid.uuid4().hex[:6]
    with TcpRelay(url.port) as registry:
        config = UplinkConfig.model_validate(
            {
                "kafka": {"bootstrap_servers": kafka_bootstrap},
                "registry": {"url": urlunsplit(url._replace(netloc=f"127.0.0.1:{registry.port}"))},
                "zenoh": {"mode": "client", "connect": [zenoh_router]},
                "topics": {"dead_letter": f"dlq.{name}"},
                "ingest": ingest,
            }
        )
        schema: dict[str, object] = {
            "type": "record",
            "name": f"Count{name}",
            "fields": [{"name": "n", "type": "long"}],
        }
        with Uplink(config), zenoh.open(zenoh_peer_config(zenoh_router, "client")) as edge:
            yield Bed(registry, edge, f"fleet.order.{name}", schema)


def test_a_batch_after_a_failed_one_waits_for_it(bed: Bed, kafka_bootstrap: str) -> None:
    first, second = bed.batch(1, 10), bed.batch(11, 10)
    bed.registry.set_mode("refuse")  # the schema cannot be registered: the first batch fails
    failed = send(bed.edge, first)
    assert failed.status == "error", failed
    bed.registry.set_mode("pass")  # the registry is back as the next batch comes
    held = send(bed.edge, second)
    assert (held.status, held.first_seq, held.last_seq) == ("held_back", 11, 20), held
    assert "batch 1.. of this stream was not produced" in held.detail
    assert send(bed.edge, first).status == "ok"  # the failed batch again, then the one after it
    assert send(bed.edge, second).status == "ok"
    assert bed.order(kafka_bootstrap, 20) == list(range(1, 21))


def test_a_batch_after_one_sent_back_for_its_schema_waits_for_it(bed: Bed, kafka_bootstrap: str) -> None:
    lean = bed.batch(1, 10, carry_schema=False)  # the uplink never read this schema
    asked = send(bed.edge, lean)
    assert asked.status == "need_schemas", asked
    held = send(bed.edge, bed.batch(11, 10))  # this one carries the schema: it could go, it waits
    assert (held.status, held.first_seq) == ("held_back", 11), held
    assert send(bed.edge, bed.batch(1, 10)).status == "ok"
    assert send(bed.edge, bed.batch(11, 10)).status == "ok"
    assert send(bed.edge, bed.batch(21, 5, carry_schema=False)).status == "ok"  # known now: no fence
    assert bed.order(kafka_bootstrap, 25) == list(range(1, 26))


def test_a_batch_after_one_refused_busy_waits_for_it(one_slot_bed: Bed, kafka_bootstrap: str) -> None:
    bed = one_slot_bed
    assert send(bed.edge, bed.batch(1, 1, stream=f"{bed.topic}.warm")).status == "ok"  # routes ready
    bed.registry.set_mode("blackhole")  # a batch of another stream holds the only slot, waiting
    pending = ask(bed.edge, bed.batch(1, 1, stream=f"{bed.topic}.other"))
    first, second = bed.batch(1, 10), bed.batch(11, 10)
    with pytest.raises(AssertionError, match="uplink busy"):
        send(bed.edge, first)  # answered busy, unread
    # on edge-1's key, a batch naming edge-2's stream: answered busy, it must not hold edge-2 back
    forged = dataclasses.replace(bed.batch(1, 1, stream=f"{bed.topic}.e2"), edge_id="edge-2")
    assert refusal(ask(bed.edge, forged, key=ingest_key("site-a", "edge-1"))) == "uplink busy: retry later"
    bed.registry.set_mode("refuse")  # the holder fails and frees the slot
    assert [reply.ok is not None for reply in pending] == [True]
    bed.registry.set_mode("pass")
    held = send(bed.edge, second)
    assert (held.status, held.first_seq, held.last_seq) == ("held_back", 11, 20), held
    assert send(bed.edge, first).status == "ok"
    assert send(bed.edge, second).status == "ok"
    assert bed.order(kafka_bootstrap, 20) == list(range(1, 21))
    later = dataclasses.replace(bed.batch(5, 1, stream=f"{bed.topic}.e2"), edge_id="edge-2")
    assert send(bed.edge, later).status == "ok"


def test_an_earlier_batch_in_hand_does_not_lift_a_busy_fence(two_slot_bed: Bed, kafka_bootstrap: str) -> None:
    bed = two_slot_bed
    assert send(bed.edge, bed.batch(1, 1)).status == "ok"  # routes ready, the schema known
    bed.registry.set_mode("blackhole")  # a batch of another stream holds a slot, waiting
    holder = ask(bed.edge, bed.batch(1, 1, stream=f"{bed.topic}.other"))
    earlier = ask(bed.edge, bed.batch(2, 9))  # the second slot: it waits behind the holder
    first, second = bed.batch(11, 10), bed.batch(21, 10)
    with pytest.raises(AssertionError, match="uplink busy"):
        send(bed.edge, first)  # answered busy, unread: the fence is up
    bed.registry.set_mode("refuse")  # the holder fails; the earlier batch goes after it
    assert [reply.ok is not None for reply in holder] == [True]
    assert [decode_ack(reply.ok.payload.to_bytes()).status for reply in earlier if reply.ok] == ["ok"]
    bed.registry.set_mode("pass")
    held = send(bed.edge, second)  # the earlier batch did not lift the fence
    assert (held.status, held.first_seq) == ("held_back", 21), held
    assert send(bed.edge, first).status == "ok"
    assert send(bed.edge, second).status == "ok"
    assert bed.order(kafka_bootstrap, 30) == list(range(1, 31))


def ask(session: zenoh.Session, batch: Batch, key: str = "") -> Any:
    """Send a batch without waiting: the replies, to iterate."""
    return session.get(
        key or ingest_key(batch.site, batch.edge_id),
        payload=encode_batch(batch, codec="zlib"),
        target=zenoh.QueryTarget.BEST_MATCHING,
        timeout=60,
    )


def refusal(replies: Any) -> str:
    """The error a query was answered with."""
    (reply,) = list(replies)
    assert reply.err is not None, "answered ok"
    return str(reply.err.payload.to_bytes().decode())
