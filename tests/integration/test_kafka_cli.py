"""``fleetlink kafka echo|send`` against a real Kafka broker and a real Apicurio Registry.

Each command runs as its own process, as a user types it; the records it writes are read back
with the stock Confluent deserializer, and records written by other producers are echoed.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import uuid
from typing import Any

import pytest
from confluent_kafka import Consumer, Producer, TopicPartition
from confluent_kafka.schema_registry import SchemaRegistryClient
from confluent_kafka.schema_registry.avro import AvroDeserializer
from confluent_kafka.serialization import MessageField, SerializationContext

from fleetlink.schemas.avro_schema import avro_schema
from fleetlink.schemas.registry import SchemaRegistry, subject_for_topic
from fleetlink.schemas.typestore import load_typestore
from tests.helpers import wait_until
from tests.integration.fault_scenario import create_topics
from tests.paths import IROBOT, ROOT

LEDS = "irobot_create_msgs/msg/LightringLeds"
BLUE = (
    "{header: {stamp: {sec: 5, nanosec: 250000000}, frame_id: ''}, leds: ["
    + ", ".join(["{red: 0, green: 0, blue: 255}"] * 6)
    + "], override_system: true}"
)


def fleetlink(*argv: str, env: dict[str, str], stdin: str | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "fleetlink", *argv],
        cwd=ROOT,
        env=env,
        input=stdin,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )


@pytest.fixture
def env(kafka_bootstrap: str, schema_registry_url: str) -> dict[str, str]:
    return {**os.environ, "KAFKA_BOOTSTRAP": kafka_bootstrap, "SCHEMA_REGISTRY_URL": schema_registry_url}


@pytest.fixture
def topic(kafka_bootstrap: str, schema_registry_url: str) -> str:
    """A fresh command topic (2 partitions) with the LightringLeds schema registered under its subject."""
    name = f"cli.{uuid.uuid4().hex[:8]}.lightring"
    create_topics(kafka_bootstrap, [name])
    schema = avro_schema(load_typestore("jazzy", [IROBOT]), LEDS, "jazzy")
    with SchemaRegistry(schema_registry_url) as registry:
        registry.register(subject_for_topic(name), schema)
    return name


def read_all(bootstrap: str, registry_url: str, topic: str) -> list[Any]:
    consumer = Consumer(
        {"bootstrap.servers": bootstrap, "group.id": f"r-{uuid.uuid4()}", "enable.auto.commit": False}
    )
    deserializer = AvroDeserializer(SchemaRegistryClient({"url": registry_url}))
    try:
        partitions = consumer.list_topics(topic, timeout=10).topics[topic].partitions
        total = sum(
            int(consumer.get_watermark_offsets(TopicPartition(topic, p), timeout=5)[1]) for p in partitions
        )
        consumer.assign([TopicPartition(topic, p, 0) for p in partitions])
        got: list[Any] = []

        def poll() -> bool:
            msg = consumer.poll(0.2)
            if msg is not None and not msg.error():
                got.append(msg)
            return len(got) >= total

        wait_until(poll, timeout=20, interval=0, message=f"{total} records read from {topic}")
        return [
            (
                m.key(),
                dict(m.headers() or []),
                m.timestamp()[1],
                deserializer(m.value(), SerializationContext(topic, MessageField.VALUE)),
            )
            for m in got
        ]
    finally:
        consumer.close()


def test_send_encodes_with_the_latest_schema_and_echo_reads_it_back(
    env: dict[str, str], topic: str, kafka_bootstrap: str, schema_registry_url: str
) -> None:
    sent = fleetlink(
        "kafka", "send", topic, BLUE, "--key", "tb4_02", "-H", "fleetlink-command-id=manual-1",
        "--timestamp", "1700000005250", env=env,
    )  # fmt: skip
    assert sent.returncode == 0, sent.stderr
    with SchemaRegistry(schema_registry_url) as registry:
        schema_id, version, _ = registry.latest(subject_for_topic(topic))
    assert f"schema id {schema_id} ({topic}-value version {version})" in sent.stdout

    # what the stock Confluent deserializer reads
    [(key, headers, timestamp, value)] = read_all(kafka_bootstrap, schema_registry_url, topic)
    assert key == b"tb4_02"
    assert headers == {"fleetlink-command-id": b"manual-1"}
    assert timestamp == 1700000005250
    assert value["header"] == {"stamp": {"sec": 5, "nanosec": 250000000}, "frame_id": ""}
    assert [(led["red"], led["green"], led["blue"]) for led in value["leds"]] == [(0, 0, 255)] * 6

    # echo: one JSON object per record, the value as the stock reader sees it
    echoed = fleetlink("kafka", "echo", topic, "--from-beginning", env=env)
    assert echoed.returncode == 0, echoed.stderr
    [line] = echoed.stdout.splitlines()
    record = json.loads(line)
    assert record["topic"] == topic
    assert record["key"] == "tb4_02"
    assert record["headers"] == {"fleetlink-command-id": "manual-1"}
    assert record["timestamp"] == 1700000005250
    assert record["schema_id"] == schema_id
    assert record["value"] == value

    # the echoed value goes back in as it came out (stdin), and lands as the same record
    again = fleetlink("kafka", "send", topic, "-", "-k", "tb4_02", env=env, stdin=json.dumps(record["value"]))
    assert again.returncode == 0, again.stderr
    assert read_all(kafka_bootstrap, schema_registry_url, topic)[-1][3] == value


def test_echo_shows_undecodable_values_and_stops_after_n(
    env: dict[str, str], topic: str, kafka_bootstrap: str
) -> None:
    producer = Producer({"bootstrap.servers": kafka_bootstrap})
    producer.produce(
        topic, key=b"\xff\xfe", value=b"not avro", headers=[("h", b"1"), ("h", b"2")], partition=0
    )
    producer.produce(topic, key=b"tb4_01", value=None, partition=0)
    assert producer.flush(10) == 0
    echoed = fleetlink("kafka", "echo", topic, "--from-beginning", "-n", "1", env=env)
    assert echoed.returncode == 0, echoed.stderr
    [line] = echoed.stdout.splitlines()
    record = json.loads(line)
    assert record["key"] == {"base64": "//4="}
    assert record["headers"] == {"h": ["1", "2"]}
    assert record["value"] is None
    assert record["value_base64"] == "bm90IGF2cm8="
    assert "magic byte 0x6e is not 0x00" in record["error"]
    both = fleetlink("kafka", "echo", topic, "--from-beginning", env=env)
    assert [json.loads(x)["value"] for x in both.stdout.splitlines()] == [None, None]  # the tombstone too


def test_echo_follows_new_records_by_default(env: dict[str, str], topic: str) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "fleetlink", "kafka", "echo", topic, "-n", "1"],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")), daemon=True)  # type: ignore[union-attr]
    reader.start()
    try:
        # records sent after it started reach it; it waits for them (no end to stop at)
        def send_one() -> bool:
            assert fleetlink("kafka", "send", topic, BLUE, "-k", "tb4_03", env=env).returncode == 0
            return proc.poll() is not None

        wait_until(send_one, timeout=45, interval=0.5, message="echo printed a record sent after it started")
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    reader.join(5)
    assert json.loads(lines[0])["key"] == "tb4_03"


def test_errors_are_named_with_exit_codes(env: dict[str, str], topic: str) -> None:
    missing = fleetlink("kafka", "echo", f"no.such.{uuid.uuid4().hex[:8]}", "--from-beginning", env=env)
    assert missing.returncode == 1
    assert "does not exist" in missing.stderr

    no_subject = fleetlink("kafka", "send", f"no.such.{uuid.uuid4().hex[:8]}", "{a: 1}", env=env)
    assert no_subject.returncode == 1
    assert "no schema registered under this subject" in no_subject.stderr

    bad_field = fleetlink("kafka", "send", topic, "{header: {stamp: {sec: x}}}", env=env)
    assert bad_field.returncode == 1
    assert "header.stamp.sec: expected an int, got 'x'" in bad_field.stderr

    native = env["SCHEMA_REGISTRY_URL"].replace("/apis/ccompat/v7", "/apis/registry/v3")
    wrong_api = fleetlink("kafka", "echo", topic, "--registry", native, env=env)
    assert wrong_api.returncode == 1
    assert f"--registry {env['SCHEMA_REGISTRY_URL']}" in wrong_api.stderr

    usage = fleetlink("kafka", "send", topic, env=env)
    assert usage.returncode == 2
