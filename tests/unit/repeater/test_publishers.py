"""One publisher per topic: reused, replaced on a new type or QoS, released by durability."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, cast

import pytest

from fleetlink.repeater.publishers import Publishers, parse_qos
from fleetlink.roswire.errors import QosParseError
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.qos import DEFAULT, TRANSIENT_LOCAL, QoS

TRANSIENT = TRANSIENT_LOCAL.to_keyexpr()


@dataclass
class FakePublisher:
    topic: str
    typename: str
    qos: QoS
    stopped: bool = False

    def stop(self) -> None:
        self.stopped = True


@dataclass
class FakeNode:
    created: list[FakePublisher] = field(default_factory=list)

    def create_publisher(self, topic: str, typename: str, qos: QoS, **_kwargs: Any) -> FakePublisher:
        pub = FakePublisher(topic, typename, qos)
        self.created.append(pub)
        return pub


def is_stopped(pub: FakePublisher) -> bool:
    return pub.stopped


def publishers(idle_ttl: float = 10.0) -> tuple[Publishers, FakeNode]:
    node = FakeNode()
    return Publishers(cast(RosNode, node), idle_ttl=idle_ttl), node


def test_reused_per_topic_and_replaced_on_another_type_or_qos() -> None:
    pubs, node = publishers()
    first = pubs.get("/r/cmd", "p/msg/A", None)
    assert pubs.get("/r/cmd", "p/msg/A", None) is first
    other = pubs.get("/r/cmd", "p/msg/B", None)
    assert other is not first
    assert cast(FakePublisher, first).stopped
    pubs.get("/r/cmd", "p/msg/B", TRANSIENT)
    assert len(node.created) == 3
    assert pubs.topics() == ["/r/cmd"]


def test_volatile_publishers_linger_transient_local_ones_go_at_once() -> None:
    pubs, node = publishers(idle_ttl=10.0)
    volatile = cast(FakePublisher, pubs.get("/a", "p/msg/A", None))
    latched = cast(FakePublisher, pubs.get("/b", "p/msg/A", TRANSIENT))
    pubs.release("/a", now=100.0)
    pubs.release("/b", now=100.0)
    assert (volatile.stopped, latched.stopped) == (False, True)  # no cache outlives the lease
    assert pubs.topics() == ["/a"]
    pubs.sweep(now=109.9)
    assert not is_stopped(volatile)
    again = cast(FakePublisher, pubs.get("/a", "p/msg/A", None))  # a new command: reused
    assert again is volatile
    pubs.sweep(now=200.0)
    assert not is_stopped(volatile)  # in use again: not idle
    pubs.release("/a", now=200.0)
    pubs.sweep(now=210.0)
    assert is_stopped(volatile)
    assert pubs.topics() == []
    pubs.release("/missing", now=0.0)
    assert len(node.created) == 2


def test_stop_all() -> None:
    pubs, node = publishers()
    pubs.get("/a", "p/msg/A", None)
    pubs.get("/b", "p/msg/A", None)
    pubs.stop_all()
    assert all(p.stopped for p in node.created)
    assert pubs.topics() == []


def test_qos_strings() -> None:
    assert parse_qos(None) == DEFAULT
    assert parse_qos("") == DEFAULT
    assert parse_qos(TRANSIENT).transient_local
    with pytest.raises(QosParseError):
        parse_qos("nonsense")
