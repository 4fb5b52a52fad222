"""Bad input never stops a pipeline, end to end (docs/reliability.md rows 18 and 22).

Row 18: random bytes put on a ROS data key (no attachment; or a valid attachment with bytes
that are not CDR of the type) become dead-letter records with the raw bytes, the reason, the
stage and the ROS key; the next message flows. Row 22: a record above Kafka's message size
becomes a dead letter carrying its size and a SHA-256 reference; the spool advances and the
batch is not retried. The edge knows the uplink's limit from its first answer (the robot's
registration), so the record never crosses the WAN: the edge writes the dead letter itself.
"""

from __future__ import annotations

import hashlib
import os
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from fleetlink.edge.agent import EdgeAgent
from fleetlink.roswire import attachment, cdr
from fleetlink.roswire.names import data_key
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.robot_watcher import STRING_HASHES
from fleetlink.schemas.typestore import load_typestore
from tests.helpers import wait_until, zenoh_peer_config
from tests.integration.e2e_stack import (
    Cloud,
    TopicReader,
    cloud,
    counter,
    edge_config,
    headers,
    site,
    unique_site,
)

STRING = "std_msgs/msg/String"
MAX_MESSAGE = 200_000
CHAT = {"name": "chat", "from": "/{robot}/chatter"}


@pytest.fixture(scope="module")
def cloud_(kafka_bootstrap: str, schema_registry_url: str) -> Iterator[Cloud]:
    with cloud(kafka_bootstrap, schema_registry_url, message_max_bytes=MAX_MESSAGE) as c:
        yield c


@pytest.fixture(scope="module")
def reader(kafka_bootstrap: str, schema_registry_url: str) -> TopicReader:
    return TopicReader(kafka_bootstrap, schema_registry_url)


def test_garbage_on_a_data_key_is_dead_lettered_and_the_next_record_flows(
    cloud_: Cloud, reader: TopicReader, tmp_path: Path
) -> None:
    topic = f"fleet.chat.{uuid.uuid4().hex[:8]}"
    site_name = unique_site()
    key = data_key(0, "/tb4_01/chatter", STRING, STRING_HASHES["jazzy"])
    no_attachment = os.urandom(64)
    not_cdr = b"\x00\x01\x00\x00" + b"\xff" * 3  # a CDR header, then a string length past the end
    with site(cloud_) as router:
        config = edge_config(
            tmp_path / "spool",
            router.endpoint,
            cloud_,
            site=site_name,
            robot_types={
                "tb4": {"match": "/tb4_*", "mappings": [CHAT | {"to": topic}]},
            },
        )
        talker = RosNode(
            "talker", "/tb4_01", config=zenoh_peer_config(router.endpoint), typestore=load_typestore("jazzy")
        )
        with EdgeAgent(config) as agent, talker as robot:
            publisher = robot.create_publisher("/tb4_01/chatter", STRING, congestion="block")
            wait_until(publisher.has_subscribers, 10, message="edge subscribed")
            publisher.publish_cdr(cdr.encode_string("before"))
            with zenoh.open(zenoh_peer_config(router.endpoint)) as vandal:
                vandal.put(key, no_attachment)
                vandal.put(key, not_cdr, attachment=attachment.encode(1, time.time_ns(), b"\x07" * 16))
                wait_until(
                    lambda: agent.snapshot()["processor"]["records"] >= 4,
                    10,
                    message="both bad samples reached the processor",
                )
            publisher.publish_cdr(cdr.encode_string("after"))
            wait_until(lambda: counter(agent, "chat", "emitted") == 2, 10)
            wait_until(lambda: agent.snapshot()["streams"]["durable"]["buffer"]["depth"] == 0, 20)
            snap = agent.snapshot()
            assert snap["mappings"]["chat"]["dead_lettered"] == 2
            assert snap["rejected_samples"] == 1

    chat = reader.read(topic, 2)
    assert [reader.value(m)["data"] for m in chat] == ["before", "after"]
    dead = reader.read_until(
        cloud_.dead_letter, lambda ms: sum(headers(m).get("fleetlink.site") == site_name for m in ms) >= 2
    )
    mine = [m for m in dead if headers(m).get("fleetlink.site") == site_name]
    assert len(mine) == 2
    first, second = headers(mine[0]), headers(mine[1])
    assert mine[0].value() == no_attachment
    assert (first["fleetlink.dlq.stage"], first["fleetlink.ros_key"]) == ("receive", key)
    assert "no rmw_zenoh attachment" in first["fleetlink.dlq.reason"]
    assert first["fleetlink.dlq.size"] == "64"
    assert mine[1].value() == not_cdr
    assert (second["fleetlink.dlq.stage"], second["fleetlink.ros_key"]) == ("decode", key)
    assert second["fleetlink.seq"] == "1"
    assert second["fleetlink.dlq.topic"] == topic
    assert {m.key() for m in mine} == {b"tb4_01"}


def test_oversized_record_is_dead_lettered_with_a_reference_and_the_spool_advances(
    cloud_: Cloud, reader: TopicReader, tmp_path: Path
) -> None:
    topic = f"fleet.chat.{uuid.uuid4().hex[:8]}"
    site_name = unique_site()
    huge = "x" * (MAX_MESSAGE + 100_000)
    # its own robot: tb4_01 still belongs to the site of the test before (robots are owned)
    with site(cloud_) as router:
        config = edge_config(
            tmp_path / "spool",
            router.endpoint,
            cloud_,
            site=site_name,
            robot_types={
                "tb4": {"match": "/tb4_*", "mappings": [CHAT | {"to": topic}]},
            },
        )
        talker = RosNode(
            "talker", "/tb4_02", config=zenoh_peer_config(router.endpoint), typestore=load_typestore("jazzy")
        )
        with EdgeAgent(config) as agent, talker as robot:
            publisher = robot.create_publisher("/tb4_02/chatter", STRING, congestion="block")
            wait_until(publisher.has_subscribers, 10, message="edge subscribed")
            # the edge learns the uplink's limit from its first ack (the robot's registration
            # event); before that it cannot know, and the uplink dead-letters instead (row 22)
            wait_until(
                lambda: agent.snapshot()["record_limit"]["learned"] is not None,
                20,
                message="the edge learned the uplink's record limit",
            )
            publisher.publish_cdr(cdr.encode_string("small 1"))
            publisher.publish_cdr(cdr.encode_string(huge))
            publisher.publish_cdr(cdr.encode_string("small 2"))
            wait_until(lambda: counter(agent, "chat", "emitted") == 2, 10)
            wait_until(
                lambda: agent.snapshot()["streams"]["durable"]["buffer"]["depth"] == 0,
                20,
                message="the spool advanced past the oversized record",
            )
            assert counter(agent, "chat", "dead_lettered") == 1
            sender = agent.snapshot()["streams"]["durable"]["sender"]
            assert sender["records_dead_lettered"] == 0  # kept off the WAN: the uplink refused nothing
            assert sender["batches_retried"] == 0  # no endless retry

    chat = reader.read(topic, 2)
    assert [reader.value(m)["data"] for m in chat] == ["small 1", "small 2"]
    dead = reader.read_until(
        cloud_.dead_letter, lambda ms: any(headers(m).get("fleetlink.site") == site_name for m in ms)
    )
    mine = [m for m in dead if headers(m).get("fleetlink.site") == site_name]
    assert len(mine) == 1
    h = headers(mine[0])
    assert mine[0].value() in (b"", None)  # too large to carry: a reference instead
    assert int(h["fleetlink.dlq.size"]) > MAX_MESSAGE
    assert h["fleetlink.dlq.topic"] == topic
    assert h["fleetlink.seq"] == "2"
    assert "uplink's Kafka limit of 200000 bytes" in h["fleetlink.dlq.reason"]
    assert mine[0].key() == b"tb4_02"
    message = cdr.encode_string(huge)  # the robot's message, as every edge-side dead letter
    assert h["fleetlink.dlq.sha256"] == hashlib.sha256(message).hexdigest()
    assert int(h["fleetlink.dlq.size"]) == len(message)
