"""Through the real registry and Kafka: records made by the generated converters are read by
confluent-kafka's stock AvroDeserializer with rosbags' values; incompatible changes are refused."""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from typing import Any

import pytest
from confluent_kafka import Consumer, KafkaError, Message, Producer
from confluent_kafka.admin import AdminClient, NewTopic
from confluent_kafka.schema_registry import SchemaRegistryClient
from confluent_kafka.schema_registry.avro import AvroDeserializer
from confluent_kafka.serialization import MessageField, SerializationContext
from rosbags.rosbag2 import Reader
from rosbags.typesys.store import Typestore

from fleetlink.schemas.avro_schema import avro_schema
from fleetlink.schemas.codec import get_codec
from fleetlink.schemas.errors import IncompatibleSchemaError
from fleetlink.schemas.registry import RegistryUnavailableError, SchemaRegistry, subject_for_topic
from fleetlink.schemas.single_object import confluent_frame
from fleetlink.schemas.typestore import load_typestore, types_from_msg
from tests.helpers import free_port, wait_until
from tests.paths import HUSKY
from tests.unit.schemas.ros_values import avro_shaped, same

BAG = HUSKY
PER_TYPE = 40


def _bag_messages(ts: Typestore) -> dict[str, list[bytes]]:
    out: dict[str, list[bytes]] = {}
    with Reader(BAG) as reader:
        for conn, _, raw in reader.messages():
            bucket = out.setdefault(conn.msgtype, [])
            if len(bucket) < PER_TYPE:
                bucket.append(bytes(raw))
            if len(out) == 3 and all(len(v) == PER_TYPE for v in out.values()):
                break
    return out


def _create_topics(bootstrap: str, names: list[str]) -> None:
    admin = AdminClient({"bootstrap.servers": bootstrap})
    futures = admin.create_topics([NewTopic(n, num_partitions=1, replication_factor=1) for n in names])
    for future in futures.values():
        future.result(timeout=30)


@pytest.fixture
def registry(schema_registry_url: str) -> Iterator[SchemaRegistry]:
    with SchemaRegistry(schema_registry_url) as reg:
        yield reg


def test_stock_deserializer_reads_what_we_produce(
    kafka_bootstrap: str, schema_registry_url: str, registry: SchemaRegistry
) -> None:
    ts = load_typestore("humble", bags=[BAG])
    batches = _bag_messages(ts)
    assert sorted(batches) == ["nav_msgs/msg/Odometry", "sensor_msgs/msg/Imu", "sensor_msgs/msg/NavSatFix"]
    run = uuid.uuid4().hex[:8]
    topics = {t: f"schemas-it-{run}.{t.split('/')[-1].lower()}" for t in batches}
    _create_topics(kafka_bootstrap, list(topics.values()))

    failures: list[str] = []

    def delivered(err: KafkaError | None, _msg: Message) -> None:
        if err is not None:
            failures.append(str(err))

    producer = Producer({"bootstrap.servers": kafka_bootstrap, "acks": "all", "enable.idempotence": True})
    for typename, payloads in batches.items():
        codec = get_codec(ts, typename, "humble")
        schema_id = registry.register(subject_for_topic(topics[typename]), codec.schema)
        assert registry.register(subject_for_topic(topics[typename]), codec.schema) == schema_id  # cached
        for cdr in payloads:
            value = confluent_frame(schema_id, codec.cdr_to_avro(cdr))
            producer.produce(topics[typename], key=b"husky", value=value, on_delivery=delivered)
            producer.poll(0)
    assert producer.flush(30) == 0
    assert failures == []

    deserializer = AvroDeserializer(SchemaRegistryClient({"url": schema_registry_url}))
    consumer = Consumer(
        {
            "bootstrap.servers": kafka_bootstrap,
            "group.id": f"schemas-it-{run}",
            "auto.offset.reset": "earliest",
        }
    )
    consumer.subscribe(list(topics.values()))
    received: dict[str, list[dict[str, Any]]] = {t: [] for t in topics.values()}

    def all_received() -> bool:
        msg = consumer.poll(0.2)
        if msg is not None and msg.error() is None:
            topic = msg.topic()
            assert topic is not None
            ctx = SerializationContext(topic, MessageField.VALUE)
            received[topic].append(deserializer(msg.value(), ctx))
        return all(len(v) == PER_TYPE for v in received.values())

    try:
        wait_until(
            all_received, timeout=30, message=f"{PER_TYPE} records on each of {sorted(topics.values())}"
        )
    finally:
        consumer.close()
    for typename, payloads in batches.items():
        got = received[topics[typename]]
        for cdr, record in zip(payloads, got, strict=True):
            assert same(record, avro_shaped(ts, ts.deserialize_cdr(cdr, typename), typename)), typename


def _store_with(definition: str) -> Typestore:
    ts = load_typestore("jazzy")
    ts.register(types_from_msg(definition, "fleet_msgs/msg/Reading"))
    return ts


def test_incompatible_change_is_refused_with_the_registry_message(registry: SchemaRegistry) -> None:
    subject = subject_for_topic(f"schemas-it-{uuid.uuid4().hex[:8]}.reading")
    v1 = avro_schema(_store_with("int32 level\nstring source\n"), "fleet_msgs/msg/Reading", "jazzy")
    compatible = avro_schema(_store_with("int32 level\nstring source\n"), "fleet_msgs/msg/Reading", "jazzy")
    v2 = avro_schema(
        _store_with("int32 level\nstring source\nfloat64 extra\n"), "fleet_msgs/msg/Reading", "jazzy"
    )

    registry.check_compatible(subject, v1)  # nothing registered yet
    first = registry.register(subject, v1)
    registry.set_compatibility(subject, "BACKWARD")
    registry.check_compatible(subject, compatible)
    assert registry.register(subject, compatible) == first

    with pytest.raises(IncompatibleSchemaError) as checked:
        registry.check_compatible(subject, v2)
    assert checked.value.subject == subject
    assert checked.value.version == 1
    assert "extra" in checked.value.registry_message

    with pytest.raises(IncompatibleSchemaError) as refused:
        registry.register(subject, v2)
    assert refused.value.subject == subject
    assert refused.value.version == 1
    assert refused.value.registry_message

    # nothing was registered under the incompatible schema
    assert registry.schema_by_id(first)["fields"] == v1["fields"]
    client = SchemaRegistryClient({"url": registry.url})
    assert client.get_versions(subject) == [1]


def test_unreachable_registry_is_reported_as_unavailable() -> None:
    url = f"http://127.0.0.1:{free_port()}/apis/ccompat/v7"
    schema = avro_schema(_store_with("int32 level\n"), "fleet_msgs/msg/Reading", "jazzy")
    with SchemaRegistry(url) as reg:
        with pytest.raises(RegistryUnavailableError) as registering:
            reg.register("down-value", schema)
        assert registering.value.subject == "down-value"
        assert url in registering.value.reason
        with pytest.raises(RegistryUnavailableError):
            reg.check_compatible("down-value", schema)
