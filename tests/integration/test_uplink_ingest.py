"""The uplink against real Kafka, registry and Zenoh: batches in, Avro records and acks out."""

from __future__ import annotations

import hashlib
import json
import uuid
from collections.abc import Iterator

import httpx
import pytest
import zenoh
from confluent_kafka import Consumer, Message
from confluent_kafka.schema_registry import SchemaRegistryClient
from confluent_kafka.schema_registry.avro import AvroDeserializer
from confluent_kafka.serialization import MessageField, SerializationContext
from prometheus_client.parser import text_string_to_metric_families
from rosbags.rosbag2 import Reader

from fleetlink.schemas.codec import get_codec
from fleetlink.schemas.single_object import fingerprint
from fleetlink.schemas.typestore import load_typestore
from fleetlink.uplink.config import UplinkConfig
from fleetlink.uplink.service import Uplink
from fleetlink.wire import Ack, Record, decode_ack, encode_batch, ingest_key, single_object
from fleetlink.wire.batch import Batch
from tests.helpers import zenoh_peer_config
from tests.paths import HUSKY


@pytest.fixture(scope="module")
def uplink_config(kafka_bootstrap: str, schema_registry_url: str, zenoh_router: str) -> UplinkConfig:
    return UplinkConfig.model_validate(
        {
            "kafka": {"bootstrap_servers": kafka_bootstrap, "message_max_bytes": 200_000},
            "registry": {"url": schema_registry_url},
            "zenoh": {"mode": "client", "connect": [zenoh_router]},
            "topics": {"dead_letter": f"dlq.{uuid.uuid4().hex[:6]}"},
            "metrics": {"listen": "127.0.0.1:0"},
        }
    )


@pytest.fixture(scope="module")
def uplink(uplink_config: UplinkConfig) -> Iterator[Uplink]:
    with Uplink(uplink_config) as service:
        yield service


@pytest.fixture(scope="module")
def edge_session(zenoh_router: str) -> Iterator[zenoh.Session]:
    with zenoh.open(zenoh_peer_config(zenoh_router, "client")) as session:
        yield session


def send(session: zenoh.Session, batch: Batch, timeout: float = 30.0) -> Ack:
    """Send like an edge does; retry while the uplink's queryable is not yet visible."""
    payload = encode_batch(batch, codec="zlib")
    for _ in range(100):
        replies = list(
            session.get(
                ingest_key(batch.site, batch.edge_id),
                payload=payload,
                target=zenoh.QueryTarget.BEST_MATCHING,
                timeout=timeout,
            )
        )
        for reply in replies:
            if reply.ok is not None:
                return decode_ack(reply.ok.payload.to_bytes())
            err = reply.err
            raise AssertionError(f"uplink answered with an error: {err.payload.to_bytes() if err else b''!r}")
    raise AssertionError("no uplink answered")


def read_topic(bootstrap: str, topic: str, count: int) -> list[Message]:
    consumer = Consumer(
        {"bootstrap.servers": bootstrap, "group.id": f"t-{uuid.uuid4()}", "auto.offset.reset": "earliest"}
    )
    consumer.subscribe([topic])
    out: list[Message] = []
    try:
        for _ in range(600):
            msg = consumer.poll(0.1)
            if msg is not None and not msg.error():
                out.append(msg)
                if len(out) >= count:
                    break
    finally:
        consumer.close()
    return out


def husky_imu(n: int) -> list[tuple[int, bytes]]:
    out: list[tuple[int, bytes]] = []
    with Reader(HUSKY) as reader:
        conns = [c for c in reader.connections if c.topic == "/imu/data"]
        for _conn, stamp, raw in reader.messages(connections=conns):
            out.append((stamp, bytes(raw)))
            if len(out) == n:
                break
    return out


def test_batch_lands_as_avro_readable_by_stock_deserializer(
    uplink: Uplink, edge_session: zenoh.Session, kafka_bootstrap: str, schema_registry_url: str
) -> None:
    ts = load_typestore("humble")
    codec = get_codec(ts, "sensor_msgs/msg/Imu", "humble")
    fp = fingerprint(codec.schema)
    topic = f"fleet.imu.{uuid.uuid4().hex[:6]}"
    msgs = husky_imu(200)
    records = tuple(
        Record(
            topic,
            f"r{i % 2}".encode(),
            single_object(fp, codec.cdr_to_avro(raw)),
            headers=(("fleetlink.robot", f"r{i % 2}".encode()),),
            timestamp_ms=stamp // 1_000_000,
            seq=i + 1,
        )
        for i, (stamp, raw) in enumerate(msgs)
    )
    ack = send(edge_session, Batch("site-a", "edge-1", "durable", 1, records, {fp: json.dumps(codec.schema)}))
    assert (ack.status, ack.first_seq, ack.last_seq, ack.failures) == ("ok", 1, 200, ())

    got = read_topic(kafka_bootstrap, topic, 200)
    assert len(got) == 200
    deserializer = AvroDeserializer(SchemaRegistryClient({"url": schema_registry_url}))
    by_seq = {}
    for msg in got:
        headers = dict(msg.headers() or [])
        value = deserializer(msg.value(), SerializationContext(topic, MessageField.VALUE))
        assert value is not None
        by_seq[msg.timestamp()[1]] = (msg.key(), headers["fleetlink.robot"], value)
    assert len(by_seq) == 200
    for stamp, raw in msgs:
        key, robot, value = by_seq[stamp // 1_000_000]
        assert key == robot
        assert value == codec.decode(raw)

    assert uplink.metrics_url is not None
    exposition = httpx.get(f"{uplink.metrics_url}/metrics").text
    families = {f.name: f for f in text_string_to_metric_families(exposition)}
    ok_batches = [
        s.value
        for s in families["fleetlink_ingest_batches"].samples
        if s.labels.get("site") == "site-a" and s.labels.get("status") == "ok"
    ]
    assert ok_batches
    assert ok_batches[0] >= 1
    delivered = sum(
        s.value
        for s in families["fleetlink_kafka_delivered"].samples
        if s.labels.get("topic") == topic and s.labels.get("result") == "ok"
    )
    assert delivered == 200


def test_unknown_schema_and_oversized_record_are_dead_lettered(
    uplink: Uplink, uplink_config: UplinkConfig, edge_session: zenoh.Session, kafka_bootstrap: str
) -> None:
    topic = f"fleet.misc.{uuid.uuid4().hex[:6]}"
    schema = {"type": "record", "name": "Blob", "fields": [{"name": "data", "type": "bytes"}]}
    fp = fingerprint(schema)
    good = Record(topic, b"k", single_object(fp, b"\x06abc"), seq=1)
    no_schema = Record(topic, b"k", single_object(b"\x01" * 8, b"\x00"), seq=2)
    huge = Record(topic, b"k", single_object(fp, b"\x80\x9a\x0c" + b"x" * 300_000), seq=3)
    after = Record(topic, b"k", single_object(fp, b"\x06xyz"), seq=4)
    ack = send(
        edge_session,
        Batch("site-a", "edge-1", "durable", 1, (good, no_schema, huge, after), {fp: json.dumps(schema)}),
    )
    assert ack.status == "ok"
    assert [(f.seq, f.dead_lettered) for f in ack.failures] == [(2, True), (3, True)]
    assert "no schema for fingerprint" in ack.failures[0].reason
    assert "MSG_SIZE_TOO_LARGE" in ack.failures[1].reason

    assert len(read_topic(kafka_bootstrap, topic, 2)) == 2
    dead = read_topic(kafka_bootstrap, uplink_config.topics.dead_letter, 2)
    reasons = {dict(m.headers() or [])["fleetlink.dlq.stage"] for m in dead}
    assert reasons == {b"register", b"produce"}
    big = next(m for m in dead if dict(m.headers() or [])["fleetlink.dlq.stage"] == b"produce")
    big_headers = dict(big.headers() or [])
    assert big.value() in (None, b"")  # too large to carry: a reference instead
    assert big_headers["fleetlink.dlq.size"] == str(len(huge.value)).encode()
    assert big_headers["fleetlink.dlq.sha256"] == hashlib.sha256(huge.value).hexdigest().encode()
    unknown = next(m for m in dead if dict(m.headers() or [])["fleetlink.dlq.stage"] == b"register")
    assert unknown.value() == no_schema.value  # raw bytes kept


def test_a_left_out_schema_the_uplink_never_read_is_asked_for_and_nothing_is_produced(
    uplink: Uplink, edge_session: zenoh.Session, kafka_bootstrap: str
) -> None:
    topic = f"fleet.lean.{uuid.uuid4().hex[:6]}"
    schema = {
        "type": "record",
        "name": f"Lean{uuid.uuid4().hex[:6]}",
        "fields": [{"name": "n", "type": "long"}],
    }
    fp = fingerprint(schema)

    def records(first: int) -> tuple[Record, ...]:
        return tuple(
            Record(topic, b"k", single_object(fp, bytes([2 * n])), seq=n) for n in range(first, first + 3)
        )

    lean = Batch("site-a", "edge-2", "durable", 1, records(1), elided=frozenset({fp}))
    refused = send(edge_session, lean)
    assert (refused.status, refused.missing_schemas, refused.first_seq, refused.last_seq) == (
        "need_schemas",
        (fp,),
        1,
        3,
    )
    ack = send(edge_session, Batch("site-a", "edge-2", "durable", 1, records(1), {fp: json.dumps(schema)}))
    assert ack.status == "ok"
    # from now on the fingerprint alone will do, from any edge
    again = send(edge_session, Batch("site-a", "edge-3", "durable", 4, records(4), elided=frozenset({fp})))
    assert (again.status, again.failures) == ("ok", ())
    got = read_topic(kafka_bootstrap, topic, 6)
    assert sorted(m.value()[-1] for m in got) == [2, 4, 6, 8, 10, 12]  # 1..3 once: the refusal produced none
