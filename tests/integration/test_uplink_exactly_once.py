"""Exactly-once batches against real Kafka, registry and Zenoh: each record once, whatever comes again.

Batches are sent as an edge whose spool is ``delivery: exactly_once`` sends them (a non-zero
origin); records are read back with ``isolation.level=read_committed``.
"""

from __future__ import annotations

import dataclasses
import time
import uuid
from collections.abc import Iterator

import pytest
import zenoh
from confluent_kafka import Consumer, TopicPartition

from fleetlink.uplink.config import UplinkConfig
from fleetlink.uplink.exactly_once import MarkKey, decode_mark
from fleetlink.uplink.service import Uplink
from fleetlink.wire import Record
from fleetlink.wire.batch import Batch
from tests.helpers import zenoh_peer_config
from tests.integration.test_uplink_ingest import send

ORIGIN = 0x1234_5678_9ABC_DEF0


def config(kafka_bootstrap: str, registry: str, router: str, marks: str, prefix: str) -> UplinkConfig:
    return UplinkConfig.model_validate(
        {
            "kafka": {"bootstrap_servers": kafka_bootstrap},
            "registry": {"url": registry},
            "zenoh": {"mode": "client", "connect": [router]},
            "topics": {"marks": marks},
            "exactly_once": {"transactional_id_prefix": prefix, "transaction_timeout": "20s"},
        }
    )


@pytest.fixture
def names() -> tuple[str, str, str]:
    tag = uuid.uuid4().hex[:8]
    return f"eo.{tag}", f"eo.marks.{tag}", f"t{tag}"


@pytest.fixture
def edge_session(zenoh_router: str) -> Iterator[zenoh.Session]:
    with zenoh.open(zenoh_peer_config(zenoh_router, "client")) as session:
        yield session


def batch(topic: str, seqs: range, *, origin: int = ORIGIN, site: str = "eo-site") -> Batch:
    records = tuple(
        Record(topic, b"r1", f"v{seq}".encode(), raw_value=True, timestamp_ms=1_700_000_000_000, seq=seq)
        for seq in seqs
    )
    return Batch(site, "eo-edge", "durable", seqs.start, records, origin=origin)


def committed_values(bootstrap: str, topic: str) -> list[bytes]:
    """Every record of ``topic`` a read_committed consumer sees, to the partition's end."""
    consumer = Consumer(
        {
            "bootstrap.servers": bootstrap,
            "group.id": f"t-{uuid.uuid4()}",
            "isolation.level": "read_committed",
            "enable.partition.eof": True,
        }
    )
    consumer.assign([TopicPartition(topic, 0, 0)])
    out: list[bytes] = []
    deadline = time.monotonic() + 30
    try:
        while time.monotonic() < deadline:
            msg = consumer.poll(0.1)
            if msg is None:
                continue
            if msg.error() is not None:
                if msg.error().code() == -191:  # _PARTITION_EOF
                    break
                continue
            out.append(msg.value() or b"")
    finally:
        consumer.close()
    return out


def values(seqs: range) -> list[bytes]:
    return [f"v{seq}".encode() for seq in seqs]


def test_a_batch_sent_again_is_written_once(
    kafka_bootstrap: str,
    schema_registry_url: str,
    zenoh_router: str,
    edge_session: zenoh.Session,
    names: tuple[str, str, str],
) -> None:
    topic, marks, prefix = names
    with Uplink(config(kafka_bootstrap, schema_registry_url, zenoh_router, marks, prefix)) as uplink:
        assert send(edge_session, batch(topic, range(1, 51))).status == "ok"
        again = send(edge_session, batch(topic, range(1, 51)))  # the ack was lost: the edge resends
        assert (again.status, again.first_seq, again.last_seq) == ("ok", 1, 50)
        overlap = send(edge_session, batch(topic, range(41, 81)))
        assert overlap.status == "ok"
        stats = uplink.exactly_once_stats
        assert stats is not None
        assert (stats.committed, stats.skipped_records, stats.takeovers) == (2, 60, 1)
    assert committed_values(kafka_bootstrap, topic) == values(range(1, 81))
    marks_seen = committed_values(kafka_bootstrap, marks)
    assert [decode_mark(v) for v in marks_seen][-1] == decode_mark(b'{"origin":"123456789abcdef0","seq":80}')


def test_a_new_spool_starts_its_seqs_again_under_a_new_origin(
    kafka_bootstrap: str,
    schema_registry_url: str,
    zenoh_router: str,
    edge_session: zenoh.Session,
    names: tuple[str, str, str],
) -> None:
    topic, marks, prefix = names
    with Uplink(config(kafka_bootstrap, schema_registry_url, zenoh_router, marks, prefix)):
        assert send(edge_session, batch(topic, range(1, 31))).status == "ok"
        fresh = dataclasses.replace(batch(topic, range(1, 11)), origin=ORIGIN + 1)
        renamed = tuple(r._replace(value=b"new" + r.value) for r in fresh.records)
        fresh = dataclasses.replace(fresh, records=renamed)
        assert send(edge_session, fresh).status == "ok"
    got = committed_values(kafka_bootstrap, topic)
    assert got == values(range(1, 31)) + [b"new" + v for v in values(range(1, 11))]


def test_a_restarted_uplink_reads_the_mark_back_and_another_fences_the_first(
    kafka_bootstrap: str,
    schema_registry_url: str,
    zenoh_router: str,
    edge_session: zenoh.Session,
    names: tuple[str, str, str],
) -> None:
    """Marks are in Kafka, not in the process: an uplink started later skips what an earlier
    one wrote. Two uplinks taking turns on one stream fence each other: never a record twice."""
    topic, marks, prefix = names
    cfg = config(kafka_bootstrap, schema_registry_url, zenoh_router, marks, prefix)
    with Uplink(cfg):
        assert send(edge_session, batch(topic, range(1, 101))).status == "ok"
    with Uplink(cfg) as second:
        assert send(edge_session, batch(topic, range(51, 151))).status == "ok"
        stats = second.exactly_once_stats
        assert stats is not None
        assert stats.skipped_records == 50
    first = Uplink(cfg).start()
    second = Uplink(cfg).start()
    try:
        for start in range(101, 301, 50):
            ack = send(edge_session, batch(topic, range(start, start + 100)))
            if ack.status != "ok":  # answered by an uplink whose producer was fenced: sent again
                ack = send(edge_session, batch(topic, range(start, start + 100)))
            assert ack.status == "ok", ack.detail
    finally:
        first.stop()
        second.stop()
    got = committed_values(kafka_bootstrap, topic)
    assert got == values(range(1, 351))
    key = MarkKey("eo-site", "eo-edge", "durable")
    assert key.transactional_id(prefix) == f"{prefix}.eo-site.eo-edge.durable"


@pytest.mark.parametrize("native", [True, False], ids=["native", "python"])
def test_a_record_kafka_refuses_goes_to_the_dead_letter_topic_in_the_transaction(
    kafka_bootstrap: str,
    schema_registry_url: str,
    zenoh_router: str,
    edge_session: zenoh.Session,
    names: tuple[str, str, str],
    native: bool,
) -> None:
    """A record larger than the producer takes is refused for good: the batch still commits,
    that record in the dead-letter topic and every other one in its topic, each once."""
    topic, marks, prefix = names
    dead_letters = f"{topic}.dlq"
    cfg = config(kafka_bootstrap, schema_registry_url, zenoh_router, marks, prefix)
    cfg = cfg.model_copy(
        update={
            "kafka": cfg.kafka.model_copy(update={"message_max_bytes": 4_000}),
            "topics": cfg.topics.model_copy(update={"dead_letter": dead_letters}),
            "ingest": cfg.ingest.model_copy(update={"native": native}),
        }
    )
    sent = batch(topic, range(1, 21))
    big = sent.records[4]._replace(value=b"x" * 10_000)
    sent = dataclasses.replace(sent, records=(*sent.records[:4], big, *sent.records[5:]))
    with Uplink(cfg) as uplink:
        ack = send(edge_session, sent)
        assert ack.status == "ok", ack.detail
        assert [(f.seq, f.dead_lettered) for f in ack.failures] == [(5, True)]
        again = send(edge_session, sent)  # the ack was lost: nothing is written twice
        assert again.status == "ok", again.detail
        stats = uplink.exactly_once_stats
        assert stats is not None
        assert stats.committed == 1
        assert stats.skipped_records == 20
    assert committed_values(kafka_bootstrap, topic) == values(range(1, 5)) + values(range(6, 21))
    assert len(committed_values(kafka_bootstrap, dead_letters)) == 1
