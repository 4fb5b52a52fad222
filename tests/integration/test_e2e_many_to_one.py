"""Many-to-one, end to end: the real bags replayed as three robots at once land in one Kafka topic.

Robots r1 and r2 replay the Husky bag's ``/imu/data``, r3 the TurtleBot3 bag's ``/imu``; one
robot type maps both topic shapes to ``fleet.imu.<run>``. Every message must be in Kafka exactly
once, in order per robot (the rmw_zenoh sequence number in ``fleetlink.seq``), with the value
rosbags decodes from the bag, read with the stock ``AvroDeserializer``.
"""

from __future__ import annotations

import threading
import uuid
from pathlib import Path

from rosbags.typesys.store import Typestore

from fleetlink.edge.agent import EdgeAgent
from fleetlink.schemas.typestore import load_typestore
from tests.integration.e2e_stack import (
    HUSKY,
    TB3,
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

IMU = "sensor_msgs/msg/Imu"


def test_three_robots_many_to_one(kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path) -> None:
    topic = f"fleet.imu.{uuid.uuid4().hex[:8]}"
    site_name = unique_site()
    expected = {
        "r1": bag_messages(HUSKY, "/imu/data"),
        "r2": bag_messages(HUSKY, "/imu/data"),
        "r3": bag_messages(TB3, "/imu"),
    }
    total = sum(len(v) for v in expected.values())
    with cloud(kafka_bootstrap, schema_registry_url) as cloud_, site(cloud_) as router:
        config = edge_config(
            tmp_path / "spool",
            router.endpoint,
            cloud_,
            site=site_name,
            robot_types={
                "rover": {
                    "match": "/r*",
                    "mappings": [
                        {"name": "imu_data", "from": "/{robot}/imu/data", "to": topic},
                        {"name": "imu", "from": "/{robot}/imu", "to": topic},
                    ],
                },
            },
        )
        robots = [
            replayer(HUSKY, "r1", router.endpoint, ["/imu/data"]),
            replayer(HUSKY, "r2", router.endpoint, ["/imu/data"]),
            replayer(TB3, "r3", router.endpoint, ["/imu"]),
        ]
        with EdgeAgent(config) as agent:
            for rep in robots:
                rep.start()
            try:
                for rep in robots:
                    assert rep.wait_for_subscribers(15), f"edge did not subscribe to {rep.robot}"
                runs = [threading.Thread(target=rep.run) for rep in robots]
                for run in runs:
                    run.start()
                for run in runs:
                    run.join(60)
                assert [r.stats.total for r in robots] == [len(expected[r]) for r in ("r1", "r2", "r3")]
                wait_received(agent, total, timeout=20)
                wait_spooled_and_acked(agent, total, timeout=40)
            finally:
                for rep in robots:
                    rep.stop()
            snap = agent.snapshot()
            assert snap["intake"]["dropped"] == 0
            assert snap["mappings"]["imu_data"]["emitted"] == 2 * len(expected["r1"])
            assert snap["mappings"]["imu"]["emitted"] == len(expected["r3"])
            assert all(s["gaps"] == 0 for s in snap["subscriptions"].values())

        reader = TopicReader(kafka_bootstrap, schema_registry_url)
        msgs = reader.read(topic, total, timeout=30)

    assert len(msgs) == total  # nothing more arrived after the expected count: no duplicates
    per_robot = by_key(msgs)
    assert sorted(per_robot) == ["r1", "r2", "r3"]
    ts: Typestore = load_typestore("jazzy")
    for robot, payloads in expected.items():
        got = per_robot[robot]
        assert seqs(got) == list(range(1, len(payloads) + 1)), f"{robot}: every message once, in order"
        first = headers(got[0])
        assert first["fleetlink.robot"] == robot
        assert first["fleetlink.site"] == site_name
        assert first["fleetlink.ros_type"] == IMU
        assert first["fleetlink.source_topic"] in (f"/{robot}/imu/data", f"/{robot}/imu")
        assert first["fleetlink.type_hash"].startswith("RIHS01_")
        for msg, raw in zip(got, payloads, strict=True):
            value = reader.value(msg)
            assert same(value, avro_shaped(ts, ts.deserialize_cdr(raw, IMU), IMU)), (robot, headers(msg))
    timestamps = [m.timestamp()[1] for m in per_robot["r1"]]
    assert timestamps == sorted(timestamps)  # rmw_zenoh source stamps, in publishing order
