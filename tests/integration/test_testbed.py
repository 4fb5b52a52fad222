"""The test bed itself: the real broker, the real registry and a real Zenoh router answer."""

from __future__ import annotations

import threading
import uuid

import zenoh
from confluent_kafka import Consumer, KafkaError, Producer
from confluent_kafka.admin import AdminClient, NewTopic
from confluent_kafka.schema_registry import SchemaRegistryClient
from confluent_kafka.schema_registry.avro import AvroDeserializer, AvroSerializer
from confluent_kafka.serialization import MessageField, SerializationContext

from fleetlink.localstack.zenoh_router import ZenohRouter
from tests.helpers import wait_until

SCHEMA = """
{"type": "record", "name": "Reading", "namespace": "fleetlink.test",
 "fields": [{"name": "robot", "type": "string"}, {"name": "value", "type": "double"},
            {"name": "seq", "type": "long"}]}
"""


def _consume_one(bootstrap: str, topic: str) -> tuple[bytes | None, bytes]:
    consumer = Consumer(
        {"bootstrap.servers": bootstrap, "group.id": f"t-{uuid.uuid4()}", "auto.offset.reset": "earliest"}
    )
    consumer.subscribe([topic])
    try:
        for _ in range(300):
            msg = consumer.poll(0.1)
            if msg is None or msg.error():
                continue
            value = msg.value()
            assert value is not None
            return msg.key(), value
    finally:
        consumer.close()
    raise AssertionError(f"no record on {topic} within 30 s")


def _client(endpoint: str) -> zenoh.Session:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", f'["{endpoint}"]')
    return zenoh.open(conf)


def test_avro_round_trip_through_real_registry(kafka_bootstrap: str, schema_registry_url: str) -> None:
    topic = f"testbed.avro.{uuid.uuid4().hex[:8]}"
    registry = SchemaRegistryClient({"url": schema_registry_url})
    serializer = AvroSerializer(registry, SCHEMA)
    record = {"robot": "tb4_01", "value": 0.25, "seq": 2**40}
    payload = serializer(record, SerializationContext(topic, MessageField.VALUE))
    assert payload is not None
    assert payload[0] == 0  # Confluent wire format: magic byte 0 + schema id
    producer = Producer({"bootstrap.servers": kafka_bootstrap, "acks": "all", "enable.idempotence": True})
    reports: list[KafkaError | None] = []
    producer.produce(topic, key=b"tb4_01", value=payload, on_delivery=lambda err, _m: reports.append(err))
    assert producer.flush(30) == 0
    assert reports == [None]

    key, value = _consume_one(kafka_bootstrap, topic)
    deserializer = AvroDeserializer(registry)
    assert key == b"tb4_01"
    assert deserializer(value, SerializationContext(topic, MessageField.VALUE)) == record
    assert f"{topic}-value" in registry.get_subjects()


def test_topic_created_and_listed_with_admin_client(kafka_bootstrap: str) -> None:
    admin = AdminClient({"bootstrap.servers": kafka_bootstrap})
    topic = f"testbed.admin.{uuid.uuid4().hex[:8]}"
    futures = admin.create_topics([NewTopic(topic, num_partitions=3, replication_factor=1)])
    futures[topic].result(timeout=30)
    # the broker learns of the new topic from the controller moments after create_topics returns
    wait_until(lambda: topic in admin.list_topics(timeout=10).topics, 10, message=f"{topic} listed")
    assert len(admin.list_topics(topic, timeout=10).topics[topic].partitions) == 3


def test_zenoh_put_through_router_reaches_subscriber(zenoh_router: str) -> None:
    got = threading.Event()
    received: list[bytes] = []

    def on_sample(sample: zenoh.Sample) -> None:
        received.append(sample.payload.to_bytes())
        got.set()

    with _client(zenoh_router) as sub_session, _client(zenoh_router) as pub_session:
        sub = sub_session.declare_subscriber("testbed/hello", on_sample)
        # a subscription propagates asynchronously: publish until the first sample lands
        for i in range(100):
            pub_session.put("testbed/hello", f"hi {i}".encode())
            if got.wait(0.05):
                break
        sub.undeclare()
    assert received
    assert received[0].startswith(b"hi ")


def test_two_routers_joined_by_tcp_link_forward_data() -> None:
    """An edge-site router linked to a cloud router: what is put at the edge arrives in the cloud."""
    got = threading.Event()
    with (
        ZenohRouter() as cloud,
        ZenohRouter(connect=(cloud.endpoint,)) as edge,
        _client(cloud.endpoint) as cloud_client,
        _client(edge.endpoint) as edge_client,
    ):
        sub = cloud_client.declare_subscriber("fleetlink/site-a/**", lambda _s: got.set())
        for _ in range(200):
            edge_client.put("fleetlink/site-a/probe", b"x")
            if got.wait(0.05):
                break
        sub.undeclare()
    assert got.is_set()
