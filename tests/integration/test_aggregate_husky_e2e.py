"""An aggregate mapping over the real Husky IMU bag, end to end, against a reference computation.

A robot publishes every ``/imu/data`` message of robot_localization_husky through rmw_zenoh, each
stamped with its recorded time (the source timestamp the edge's event-time windows follow).
The edge aggregates it into 1 s tumbling windows; the records cross the WAN to the uplink, land
in Kafka and are read back with the stock AvroDeserializer. numpy, over the same bag read with
rosbags, computes the same windows; every window and every statistic must agree.
"""

from __future__ import annotations

import math
import uuid
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag2 import Reader

from fleetlink.edge.agent import EdgeAgent
from fleetlink.roswire.node import RosNode
from fleetlink.schemas.typestore import load_typestore
from tests.helpers import wait_until, zenoh_peer_config
from tests.integration.e2e_stack import HUSKY, TopicReader, cloud, edge_brief, edge_config, site, unique_site

IMU = "sensor_msgs/msg/Imu"
S = 1_000_000_000
FIELDS = ["linear_acceleration.x", "linear_acceleration.y", "linear_acceleration.z", "angular_velocity.z"]
OPS = ["count", "mean", "min", "max", "last", "stddev"]
EXACT = ("count", "min", "max", "last")  # the others are sums of floats: equal up to rounding


def bag_imu() -> tuple[list[tuple[int, bytes]], dict[str, np.ndarray]]:
    """``(recorded ns, CDR)`` of every message, and each aggregated field as a numpy column."""
    ts = load_typestore("jazzy")
    messages: list[tuple[int, bytes]] = []
    columns: dict[str, list[float]] = {f: [] for f in FIELDS}
    with Reader(HUSKY) as reader:
        conns = [c for c in reader.connections if c.topic == "/imu/data"]
        for _, stamp, raw in reader.messages(connections=conns):
            messages.append((stamp, bytes(raw)))
            msg = ts.deserialize_cdr(bytes(raw), IMU)
            for path in FIELDS:
                value: Any = msg
                for part in path.split("."):
                    value = getattr(value, part)
                columns[path].append(float(value))
    return messages, {f.replace(".", "_"): np.array(v) for f, v in columns.items()}


def reference(stamps: np.ndarray, columns: dict[str, np.ndarray]) -> list[dict[str, Any]]:
    """Every non-empty 1 s window aligned on the epoch, in order: numpy over the bag's values."""
    index = stamps // S
    out = []
    for k in np.unique(index):
        inside = index == k
        newest = stamps[inside].max()
        last = int(np.flatnonzero(inside & (stamps == newest))[-1])  # ties: the later message
        record: dict[str, Any] = {
            "robot": "husky_1",
            "window_start_ns": int(k) * S,
            "window_end_ns": (int(k) + 1) * S,
            "count": int(inside.sum()),
        }
        for name, column in columns.items():
            values = column[inside]
            record.update(
                {
                    f"{name}_count": len(values),
                    f"{name}_mean": float(values.mean()),
                    f"{name}_min": float(values.min()),
                    f"{name}_max": float(values.max()),
                    f"{name}_last": float(column[last]),
                    f"{name}_stddev": float(values.std()),
                }
            )
        out.append(record)
    return out


def same_window(got: dict[str, Any], want: dict[str, Any]) -> bool:
    if set(got) != set(want):
        return False
    for key, value in want.items():
        if key.endswith(("_mean", "_stddev")):
            if not math.isclose(got[key], value, rel_tol=1e-9, abs_tol=1e-12):
                return False
        elif got[key] != value:
            return False
    return True


def test_imu_aggregates_in_kafka_equal_numpy_over_the_bag(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    topic = f"fleet.imu_1s.{uuid.uuid4().hex[:8]}"
    messages, columns = bag_imu()
    want = reference(np.array([m[0] for m in messages], dtype=np.int64), columns)
    assert len(messages) == 11_865  # the whole bag, ~395 s
    assert len(want) > 390
    mapping = {
        "name": "imu_1s",
        "from": "/{robot}/imu/data",
        "to": topic,
        "type": IMU,
        "stages": [{"type": "aggregate", "window": "1s", "fields": FIELDS, "ops": OPS, "idle_timeout": "3s"}],
    }
    with cloud(kafka_bootstrap, schema_registry_url) as cloud_, site(cloud_) as router:
        config = edge_config(
            tmp_path / "spool",
            router.endpoint,
            cloud_,
            site=unique_site(),
            robot_types={"husky": {"match": "/husky_*", "mappings": [mapping]}},
        )
        with (
            EdgeAgent(config) as agent,
            RosNode(
                "imu",
                "/husky_1",
                config=zenoh_peer_config(router.endpoint),
                typestore=load_typestore("jazzy"),
            ) as node,
        ):
            publisher = node.create_publisher("/husky_1/imu/data", IMU, congestion="block")
            wait_until(publisher.has_subscribers, 15, message="edge subscribed to /husky_1/imu/data")
            for stamp, raw in messages:
                publisher.publish_cdr(raw, source_ts_ns=stamp)
            # the last window closes on the idle timeout (processing time) after the last sample
            try:
                msgs = TopicReader(kafka_bootstrap, schema_registry_url).read(topic, len(want), timeout=40)
            except AssertionError as exc:  # say where the windows stopped: stage, spool, WAN
                raise AssertionError(f"{exc}; edge: {edge_brief(agent, 'stages')}") from None
            stages = agent.snapshot()["stages"]["imu_1s"]["aggregate"]
    assert len(msgs) == len(want)  # and nothing followed the expected windows
    assert stages["received"] == len(messages)
    assert (stages["late"], stages["errors"], stages["nan"], stages["emitted"]) == (0, 0, 0, len(want))
    reader = TopicReader(kafka_bootstrap, schema_registry_url)
    got = [reader.value(m) for m in msgs]
    assert [g["window_start_ns"] for g in got] == [w["window_start_ns"] for w in want]
    for g, w in zip(got, want, strict=True):
        assert same_window(g, w), (g, w)
    assert sum(g["count"] for g in got) == len(messages)
    assert {m.key() for m in msgs} == {b"husky_1"}
    assert [m.timestamp()[1] for m in msgs] == [w["window_end_ns"] // 1_000_000 for w in want]


@pytest.mark.parametrize(
    ("got", "verdict"),
    [
        ({"a_mean": 1.0 + 1e-12, "count": 3}, True),
        ({"a_mean": 1.001, "count": 3}, False),
        ({"a_mean": 1.0, "count": 4}, False),
        ({"a_mean": 1.0}, False),
    ],
)
def test_same_window_sums_up_to_rounding_the_rest_exactly(got: dict[str, Any], verdict: bool) -> None:
    assert same_window(got, {"a_mean": 1.0, "count": 3}) is verdict
