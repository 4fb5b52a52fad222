"""One-to-one, one-to-many (a message field in the topic template) and many-to-many, end to end.

robots (real bags, or a String publisher) -> site router -> edge agent -> cloud router -> uplink
-> Kafka; every record is read back with the stock AvroDeserializer.
"""

from __future__ import annotations

import threading
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from fleetlink.common.metrics import MetricsRecorder
from fleetlink.edge.admin.agent_backend import snapshot_from_agent
from fleetlink.edge.admin.telemetry import EdgeTelemetry
from fleetlink.edge.agent import EdgeAgent
from fleetlink.roswire import cdr
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.publisher import RosPublisher
from fleetlink.schemas.typestore import load_typestore
from tests.helpers import wait_until, zenoh_peer_config
from tests.integration.e2e_stack import (
    HUSKY,
    TB3,
    Cloud,
    TopicReader,
    bag_messages,
    by_key,
    cloud,
    edge_config,
    headers,
    replayer,
    seqs,
    site,
    unique_site,
    wait_received,
    wait_spooled_and_acked,
)
from tests.unit.schemas.ros_values import avro_shaped, same

STRING = "std_msgs/msg/String"


@pytest.fixture(scope="module")
def cloud_(kafka_bootstrap: str, schema_registry_url: str) -> Iterator[Cloud]:
    with cloud(kafka_bootstrap, schema_registry_url) as c:
        yield c


@pytest.fixture(scope="module")
def reader(kafka_bootstrap: str, schema_registry_url: str) -> TopicReader:
    return TopicReader(kafka_bootstrap, schema_registry_url)


@pytest.mark.parametrize(("delivery", "stream"), [("at_least_once", "durable"), ("best_effort", "memory")])
def test_one_to_one(cloud_: Cloud, reader: TopicReader, tmp_path: Path, delivery: str, stream: str) -> None:
    """One ROS topic of one robot -> one Kafka topic (site-level mapping, fixed key), through the
    durable spool or, for a ``best_effort`` mapping, the memory buffer."""
    topic = f"fleet.gps.{uuid.uuid4().hex[:8]}"
    expected = bag_messages(HUSKY, "/fix")
    with site(cloud_) as router:
        config = edge_config(
            tmp_path / "spool",
            router.endpoint,
            cloud_,
            site=unique_site(),
            mappings=[
                {
                    "name": "gps",
                    "from": "/husky_7/fix",
                    "to": topic,
                    "key": "husky_7",
                    "type": "sensor_msgs/msg/NavSatFix",
                    "delivery": delivery,
                },
            ],
        )
        with EdgeAgent(config) as agent:
            wait_until(
                lambda: "/husky_7/fix" in agent.subscribed_topics(),
                10,
                message="eager subscription of a mapping with a declared type",
            )
            with replayer(HUSKY, "husky_7", router.endpoint, ["/fix"]) as robot:
                assert robot.wait_for_subscribers(10)
                assert robot.run().total == len(expected)
                wait_received(agent, len(expected), timeout=20)  # before the robot's session closes
            wait_spooled_and_acked(agent, len(expected), timeout=30, stream_name=stream)
            other = "memory" if stream == "durable" else "durable"
            assert agent.snapshot()["streams"][other]["sender"]["records_sent"] == 0
    msgs = reader.read(topic, len(expected))
    assert len(msgs) == len(expected)
    assert {m.key() for m in msgs} == {b"husky_7"}
    assert seqs(msgs) == list(range(1, len(expected) + 1))
    ts = load_typestore("jazzy")
    kind = "sensor_msgs/msg/NavSatFix"
    for msg, raw in zip(msgs, expected, strict=True):
        assert same(reader.value(msg), avro_shaped(ts, ts.deserialize_cdr(raw, kind), kind))
    assert headers(msgs[0])["fleetlink.mapping"] == "gps"
    assert "fleetlink.robot" not in headers(msgs[0])  # the pattern captures no robot


def test_one_to_many_by_message_field(cloud_: Cloud, reader: TopicReader, tmp_path: Path) -> None:
    """One ROS topic -> a Kafka topic per zone, chosen by a field of each message; a zone that is
    not a legal topic name goes to the dead-letter topic, and the next message flows."""
    run = uuid.uuid4().hex[:8]
    zones = ["zone_a", "zone_b", "zone_c"]
    texts = [zones[i % 3] for i in range(300)]
    texts[150] = "no such/zone"
    site_name = unique_site()
    with site(cloud_) as router:
        config = edge_config(
            tmp_path / "spool",
            router.endpoint,
            cloud_,
            site=site_name,
            mappings=[
                {"name": "tasks", "from": "/{robot}/task_status", "to": f"fleet.tasks.{run}.{{msg.data}}"},
            ],
        )
        robot = RosNode(
            "tasks", "/tb4_01", config=zenoh_peer_config(router.endpoint), typestore=load_typestore("jazzy")
        )
        with EdgeAgent(config) as agent, robot as node:
            publisher = node.create_publisher("/tb4_01/task_status", STRING, congestion="block")
            wait_until(publisher.has_subscribers, 10, message="edge subscribed to /tb4_01/task_status")
            for text in texts:
                publisher.publish_cdr(cdr.encode_string(text))
            wait_spooled_and_acked(agent, len(texts), timeout=30)
            assert agent.snapshot()["mappings"]["tasks"] == {
                "received": 300,
                "emitted": 299,
                "dropped": 0,
                "dead_lettered": 1,
                "type_mismatch": 0,
            }
    for zone in zones:
        positions = [i + 1 for i, t in enumerate(texts) if t == zone]
        msgs = reader.read(f"fleet.tasks.{run}.{zone}", len(positions))
        assert len(msgs) == len(positions) == (99 if zone == "zone_a" else 100)
        assert [reader.value(m) for m in msgs] == [{"data": zone}] * len(msgs)
        assert seqs(msgs) == positions  # each zone's records in publishing order
        assert {m.key() for m in msgs} == {b"tb4_01"}
    dead = reader.read_until(
        cloud_.dead_letter, lambda ms: any(headers(m).get("fleetlink.site") == site_name for m in ms)
    )
    mine = [m for m in dead if headers(m).get("fleetlink.site") == site_name]
    assert len(mine) == 1
    h = headers(mine[0])
    assert mine[0].value() == cdr.encode_string("no such/zone")
    assert (h["fleetlink.dlq.stage"], h["fleetlink.seq"], h["fleetlink.mapping"]) == ("map", "151", "tasks")
    assert "no such/zone" in h["fleetlink.dlq.reason"]
    assert h["fleetlink.dlq.topic"] == f"fleet.tasks.{run}.{{msg.data}}"


def test_many_to_many(cloud_: Cloud, reader: TopicReader, tmp_path: Path) -> None:
    """``/{robot}/{sensor}`` -> ``fleet.<run>.{sensor}``: two robots, three sensors, three topics."""
    run = uuid.uuid4().hex[:8]
    sensors = {
        "imu": "sensor_msgs/msg/Imu",
        "odom": "nav_msgs/msg/Odometry",
        "scan": "sensor_msgs/msg/LaserScan",
    }
    expected = {s: bag_messages(TB3, f"/{s}") for s in sensors}
    robots = ("tb3_1", "tb3_2")
    total = len(robots) * sum(len(v) for v in expected.values())
    with site(cloud_) as router:
        config = edge_config(
            tmp_path / "spool",
            router.endpoint,
            cloud_,
            site=unique_site(),
            robot_types={
                "tb3": {
                    "match": "/tb3_*",
                    "mappings": [
                        {"name": "sensors", "from": "/{robot}/{sensor}", "to": f"fleet.{run}.{{sensor}}"}
                    ],
                },
            },
        )
        with EdgeAgent(config) as agent:
            replays = [replayer(TB3, r, router.endpoint, [f"/{s}" for s in sensors]).start() for r in robots]
            try:
                for rep in replays:
                    assert rep.wait_for_subscribers(15)
                threads = [threading.Thread(target=rep.run) for rep in replays]
                for thread in threads:
                    thread.start()
                for thread in threads:
                    thread.join(60)
                wait_received(agent, total, timeout=20)
            finally:
                for rep in replays:
                    rep.stop()
            wait_spooled_and_acked(agent, total, timeout=40)
    ts = load_typestore("jazzy")
    for sensor, kind in sensors.items():
        msgs = reader.read(f"fleet.{run}.{sensor}", len(robots) * len(expected[sensor]))
        assert len(msgs) == len(robots) * len(expected[sensor])
        per_robot = by_key(msgs)
        assert sorted(per_robot) == list(robots)
        for robot in robots:
            got = per_robot[robot]
            assert seqs(got) == list(range(1, len(expected[sensor]) + 1))
            assert {headers(m)["fleetlink.source_topic"] for m in got} == {f"/{robot}/{sensor}"}
            for msg, raw in list(zip(got, expected[sensor], strict=True))[::7]:  # every 7th record
                assert same(reader.value(msg), avro_shaped(ts, ts.deserialize_cdr(raw, kind), kind))


@contextmanager
def unregistered_talker(
    cloud_: Cloud, tmp_path: Path, hold: str, topic: str = "fleet.chatter"
) -> Iterator[tuple[EdgeAgent, RosPublisher]]:
    """An edge whose robots register only explicitly (``registration.hold``: ``hold``; robot type
    ``tb4`` maps ``/{robot}/chatter`` to ``topic``), and robot tb4_07 publishing
    ``/tb4_07/chatter``, not registered."""
    chat = {"name": "chatter", "from": "/{robot}/chatter", "to": topic, "type": STRING}
    with site(cloud_) as router:
        config = edge_config(
            tmp_path / "spool",
            router.endpoint,
            cloud_,
            site=unique_site(),
            robot_types={"tb4": {"match": "/tb4_*", "mappings": [chat]}},
            registration={"discover": False, "grace_period": "1s", "hold": hold},
        )
        robot = RosNode(
            "talker", "/tb4_07", config=zenoh_peer_config(router.endpoint), typestore=load_typestore("jazzy")
        )
        with EdgeAgent(config) as agent, robot as node:
            publisher = node.create_publisher("/tb4_07/chatter", STRING, congestion="block")
            wait_until(publisher.has_subscribers, 10, message="the edge receives /tb4_*/chatter")
            yield agent, publisher


def chatter(agent: EdgeAgent) -> dict[str, int]:
    counters: dict[str, int] = agent.snapshot()["subscriptions"].get("/tb4_07/chatter", {})
    return counters


def test_samples_no_mapping_takes_are_counted_not_lost_silently(cloud_: Cloud, tmp_path: Path) -> None:
    """A robot whose samples arrive while it is not registered (here registration is explicit and
    it never registers) makes no record: its samples wait ``registration.hold`` for it, then each
    is counted as ``unmapped`` on its topic, the general path's and the data plane's alike, and
    none is reported delivered."""
    with unregistered_talker(cloud_, tmp_path, hold="1s") as (agent, publisher):
        for i in range(100):
            publisher.publish_cdr(cdr.encode_string(f"tb4_07:{i}"))
        wait_until(lambda: chatter(agent).get("received") == 100, 20, message="the 100 samples taken")
        wait_until(lambda: chatter(agent)["unmapped"] == 100, 10, message="given up after the hold")
        for i in range(100, 200):  # the topic was given up: not held again, counted at once
            publisher.publish_cdr(cdr.encode_string(f"tb4_07:{i}"))
        wait_until(lambda: chatter(agent).get("received") == 200, 20, message="the 200 samples taken")
        counters = chatter(agent)
        snap = agent.snapshot()
        assert "tb4_07" not in snap.get("robots", {})
        assert snap["early"]["held"] == snap["early"]["expired"] == 100
        metrics = MetricsRecorder()
        EdgeTelemetry(metrics).observe(snapshot_from_agent(snap, agent.config), robots=0)
        assert metrics.value("fleetlink_unmapped_samples", topic="/tb4_07/chatter") == 200
    assert (counters["unmapped"], counters["waiting"], counters["delivered"], counters["missing"]) == (
        200,
        0,
        0,
        0,
    ), counters


def test_samples_before_their_robots_registration_reach_kafka_in_order(
    cloud_: Cloud, reader: TopicReader, tmp_path: Path
) -> None:
    """A robot that publishes before its registration (discovery trails a robot that starts at
    once; here it registers explicitly, late): its first samples wait for the registration and
    reach Kafka first, in order, none lost, none counted as unmapped."""
    topic = f"fleet.chatter.{uuid.uuid4().hex[:8]}"
    with unregistered_talker(cloud_, tmp_path, hold="30s", topic=topic) as (agent, publisher):
        for i in range(50):
            publisher.publish_cdr(cdr.encode_string(f"tb4_07:{i}"))
        wait_until(lambda: chatter(agent).get("waiting") == 50, 20, message="50 samples waiting")
        assert agent.snapshot()["streams"]["durable"]["buffer"]["appended"] == 0
        agent.register_robot("tb4", "tb4_07")  # as a message on /fleetlink/register does
        for i in range(50, 80):
            publisher.publish_cdr(cdr.encode_string(f"tb4_07:{i}"))
        wait_spooled_and_acked(agent, 80 + 1, 20)  # and the registration event
        counters = chatter(agent)
        early = agent.snapshot()["early"]
    mine = reader.read(topic, 80)
    assert [reader.value(m)["data"] for m in mine] == [f"tb4_07:{i}" for i in range(80)]
    assert seqs(mine) == list(range(1, 81))
    assert (counters["received"], counters["delivered"], counters["unmapped"], counters["waiting"]) == (
        80,
        80,
        0,
        0,
    )
    assert (early["held"], early["released"], early["expired"]) == (50, 50, 0)
