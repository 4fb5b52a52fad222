"""The real bags replayed through a zenoh router arrive complete and decode to the bag's values."""

from __future__ import annotations

import dataclasses
import itertools
import math
import threading
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from fleetlink.roswire.node import RosNode
from fleetlink.roswire.replay import BagReplayer, robot_topic
from fleetlink.roswire.subscriber import RosSample
from fleetlink.schemas.typestore import load_typestore, register_types, types_from_bag
from tests.helpers import wait_until, zenoh_peer_config
from tests.paths import BAGS

_domains = itertools.count(301)


def values(ts: Typestore, obj: Any) -> Any:
    """A message as plain nested values (fields only, no constants; NaN made comparable)."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        names = [name for name, _ in ts.fielddefs[obj.__msgtype__][1]]  # type: ignore[attr-defined]
        return {name: values(ts, getattr(obj, name)) for name in names}
    if isinstance(obj, np.ndarray):
        return [values(ts, v) for v in obj.tolist()]
    if isinstance(obj, list | tuple):
        return [values(ts, v) for v in obj]
    if isinstance(obj, float) and math.isnan(obj):
        return "NaN"
    return obj


def bag_records(bag: Path) -> dict[str, list[bytes]]:
    out: dict[str, list[bytes]] = defaultdict(list)
    with Reader(bag) as reader:
        for conn, _, raw in reader.messages():
            out[conn.topic].append(bytes(raw))
    return out


@pytest.mark.parametrize("bag_name", ["fuse_turtlebot3_sim", "robot_localization_husky"])
def test_every_message_of_a_real_bag_is_received_and_decodes_to_the_bag_values(
    zenoh_router: str, bag_name: str
) -> None:
    bag = BAGS / bag_name
    domain = next(_domains)
    expected = bag_records(bag)
    with Reader(bag) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
    # The reader decodes with the distro it runs (jazzy); the reference decodes with the
    # bag's own definitions in the Humble store, as the README says they were recorded.
    receiver_ts = load_typestore("jazzy", bags=[bag])
    reference_ts = get_typestore(Stores.ROS2_HUMBLE)
    register_types(reference_ts, types_from_bag(bag), str(bag))
    received: dict[str, list[RosSample]] = defaultdict(list)
    lock = threading.Lock()

    def keep(sample: RosSample) -> None:
        with lock:
            received[sample.topic].append(sample)

    with RosNode(
        "recorder", domain_id=domain, config=zenoh_peer_config(zenoh_router), typestore=receiver_ts
    ) as recorder:
        subs = [
            recorder.create_subscriber(robot_topic("husky_07", t), msgtype, keep)
            for t, msgtype in types.items()
        ]
        with BagReplayer(
            bag, "husky_07", config=zenoh_peer_config(zenoh_router), domain_id=domain, rate=0
        ) as replayer:
            assert replayer.wait_for_subscribers(timeout=10)
            stats = replayer.run()
        total = sum(len(v) for v in expected.values())
        assert stats.total == total
        wait_until(
            lambda: sum(len(v) for v in received.values()) >= total,
            timeout=20,
            message=f"all {total} messages received",
        )
        for sub in subs:
            assert sub.stats.rejected == 0
            assert sub.stats.gaps == 0
            assert sub.stats.duplicates == 0
    assert sorted(received) == sorted(robot_topic("husky_07", t) for t in expected)
    for topic, raws in expected.items():
        got = received[robot_topic("husky_07", topic)]
        assert len(got) == len(raws), topic
        assert [s.seq for s in got] == list(range(1, len(raws) + 1))
        msgtype = types[topic]
        for sample, raw in zip(got, raws, strict=True):
            assert sample.typename == msgtype
            assert values(receiver_ts, receiver_ts.deserialize_cdr(sample.payload, msgtype)) == values(
                reference_ts, reference_ts.deserialize_cdr(raw, msgtype)
            ), topic


def test_replay_follows_recorded_timing_scaled_by_rate(zenoh_router: str) -> None:
    bag = BAGS / "fuse_turtlebot3_sim"
    domain = next(_domains)
    arrivals: list[int] = []
    with RosNode("recorder", domain_id=domain, config=zenoh_peer_config(zenoh_router)) as recorder:
        recorder.create_subscriber(
            robot_topic("tb4_01", "/scan"),
            "sensor_msgs/msg/LaserScan",
            lambda s: arrivals.append(s.received_ns),
            type_hash="RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828",
        )
        # the timing is under test, not the way: the scans (KEEP_LAST, which rmw_zenoh drops when
        # the way is full, as on a loaded machine) wait for room instead
        with BagReplayer(
            bag,
            "tb4_01",
            config=zenoh_peer_config(zenoh_router),
            domain_id=domain,
            rate=50,
            topics=["/scan"],
            congestion="block",
        ) as replayer:
            assert replayer.publishers["/scan"].congestion == "block"
            assert replayer.wait_for_subscribers(timeout=10)
            stats = replayer.run()
            # while both sessions are open: the last scans may still be on their way
            try:
                wait_until(lambda: len(arrivals) >= 457, timeout=5, message="all 457 scans")
            except AssertionError as exc:
                raise AssertionError(f"{exc}: {len(arrivals)} arrived") from None
    recorded_s = 91.1  # first to last /scan message in the recording
    assert stats.published["/scan"] == 457
    assert len(arrivals) == 457
    spread = (arrivals[-1] - arrivals[0]) / 1e9
    assert recorded_s / 50 * 0.9 < spread < recorded_s / 50 * 1.5
    assert stats.max_lateness_s < 0.5
