"""Router-level downsampling of raw ROS topics on the WAN link (deploy/zenoh/edge-router.json5).

A robot on site A publishes an IMU topic at ~50 Hz for ~2 s. The edge router forwards it to the
cloud (raw_to_cloud / raw_from open the ACLs for it), where the shipped rule ``*/**/imu/**``
at 5 Hz applies on WAN egress; fleetlink keys have no rule and pass in full. A second robot on
the site network still receives every sample: downsampling touches the WAN link only.

The publisher is paced by a schedule (Event.wait until the next slot); all synchronisation is
by waiting on conditions.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import pytest
import zenoh

from tests.helpers import wait_until
from tests.integration.zenoh_topology import (
    Collector,
    client_config,
    make_bundle,
    opened,
    tls_cloud,
    tls_edge,
    uplink_config,
)

RATE_HZ = 50.0
COUNT = 100  # ~2 s at 50 Hz
RULE_HZ = 5.0  # the shipped rule for */**/imu/**
IMU = "sensor_msgs::msg::dds_::Imu_/RIHS01_7d9a00ff48f7a08f8c4b57fdbf3a4e8a2d2f0d3c1b5e6a7f8091a2b3c4d5e6f7"
RAW_KEYS = ["*/**/imu/**"]


def imu_key(robot: str) -> str:
    return f"0/{robot}/imu/{IMU}"


@dataclass
class Setup:
    robot: zenoh.Session
    at_cloud_raw: Collector
    at_cloud_fleetlink: Collector
    on_site_raw: Collector


@pytest.fixture
def setup(tmp_path: Path) -> Iterator[Setup]:
    bundle = make_bundle(tmp_path)
    with (
        tls_cloud(bundle, raw_from={"site-a": RAW_KEYS}) as cloud,
        tls_edge(bundle, "site-a", cloud.endpoint, raw_to_cloud=RAW_KEYS) as edge,
        opened(uplink_config(bundle, cloud.endpoint)) as uplink,
        opened(client_config(edge.endpoint)) as robot,
        opened(client_config(edge.endpoint)) as neighbour,
    ):
        s = Setup(robot, Collector(), Collector(), Collector())
        keep = [
            uplink.declare_subscriber("*/**/imu/**", s.at_cloud_raw),
            uplink.declare_subscriber("fleetlink/site-a/**", s.at_cloud_fleetlink),
            neighbour.declare_subscriber("0/**", s.on_site_raw),
        ]
        # Both paths are up once one sample of each has crossed the WAN.
        wait_until(
            lambda: (robot.put("fleetlink/site-a/events/warm-up", b""), s.at_cloud_fleetlink.items)[1],
            10,
            message="fleetlink path up",
        )
        wait_until(
            lambda: (robot.put(imu_key("warm-up"), b""), s.at_cloud_raw.items)[1], 10, message="raw path up"
        )
        yield s
        del keep


def publish_paced(session: zenoh.Session, keys: Sequence[str], *, count: int, rate_hz: float) -> float:
    """Put ``count`` samples on each key at ``rate_hz``; returns the seconds it took.

    Congestion control BLOCK: a sample is never dropped for a full queue, so every drop counted
    at the cloud is the downsampler's."""
    pace = threading.Event()  # never set: wait() is the pacing timer
    start = time.monotonic()
    for i in range(count):
        for key in keys:
            session.put(key, i.to_bytes(4, "big"), congestion_control=zenoh.CongestionControl.BLOCK)
        pace.wait(max(0.0, start + (i + 1) / rate_hz - time.monotonic()))
    return time.monotonic() - start


def _count(collector: Collector, key: str) -> int:
    return sum(1 for k in collector.key_exprs() if k == key)


def test_raw_topic_is_downsampled_on_the_wan_while_fleetlink_keys_pass(setup: Setup) -> None:
    raw, events = imu_key("robot1"), "fleetlink/site-a/events/robot1"
    seconds = publish_paced(setup.robot, [raw, events], count=COUNT, rate_hz=RATE_HZ)
    # The fleetlink samples were put after each raw one on the same link: once the last has
    # arrived, every raw sample the router let through has arrived too.
    wait_until(
        lambda: _count(setup.at_cloud_fleetlink, events) == COUNT,
        10,
        message="all fleetlink samples at the cloud",
    )
    wait_until(lambda: _count(setup.on_site_raw, raw) == COUNT, 10, message="all raw samples on site")
    crossed = _count(setup.at_cloud_raw, raw)
    budget = seconds * RULE_HZ + 2  # the first sample of a window passes, plus jitter
    print(
        f"\nraw: {COUNT} published in {seconds:.2f} s, {crossed} crossed the WAN "
        f"({crossed / seconds:.1f} Hz); fleetlink: {COUNT}/{COUNT}"
    )
    assert seconds >= 1.9  # really ~50 Hz for ~2 s
    assert 0.5 * seconds * RULE_HZ <= crossed <= budget


def test_a_rule_rate_is_shared_by_every_key_it_matches(setup: Setup) -> None:
    # One rule, two robots: 5 Hz is the budget of the rule on the link, not of each key.
    keys = [imu_key("robot1"), imu_key("robot2")]
    seconds = publish_paced(
        setup.robot, [*keys, "fleetlink/site-a/events/last"], count=COUNT, rate_hz=RATE_HZ
    )
    wait_until(
        lambda: _count(setup.at_cloud_fleetlink, "fleetlink/site-a/events/last") == COUNT,
        10,
        message="all fleetlink samples at the cloud",
    )
    crossed = sum(_count(setup.at_cloud_raw, key) for key in keys)
    print(f"\ntwo robots x {COUNT} in {seconds:.2f} s: {crossed} raw samples crossed in total")
    assert crossed <= seconds * RULE_HZ + 2
    # the site's own link is another way from the cloud's: the last sample at the cloud says
    # nothing of what the neighbour has received yet (its samples were put with BLOCK: all come)
    wait_until(
        lambda: all(_count(setup.on_site_raw, key) == COUNT for key in keys), 10, message="all raw on site"
    )
