"""The end-to-end test bed: robots -> site router -> edge agent -> (WAN) -> cloud router -> uplink -> Kafka.

Real pieces only: Zenoh routers (router-mode sessions), the uplink service, Kafka and the schema
registry from the session fixtures, the edge agent, robots replayed from the real bags. Each
test gets its own site name and topic suffix, so tests sharing one uplink and one broker never
see each other's records.
"""

from __future__ import annotations

import json
import time
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from confluent_kafka import Consumer, Message, TopicPartition
from confluent_kafka.schema_registry import SchemaRegistryClient
from confluent_kafka.schema_registry.avro import AvroDeserializer
from confluent_kafka.serialization import MessageField, SerializationContext
from rosbags.rosbag2 import Reader

from fleetlink.common.zenoh_configs import render_router_config
from fleetlink.edge.agent import EdgeAgent
from fleetlink.edge.config import EdgeConfig
from fleetlink.localstack.zenoh_router import ZenohRouter
from fleetlink.roswire.replay import BagReplayer
from fleetlink.schemas.registry import on_a_live_connection
from fleetlink.uplink.config import UplinkConfig
from fleetlink.uplink.service import Uplink
from tests.helpers import wait_until, zenoh_peer_config
from tests.paths import BAGS, DEPLOY

HUSKY = BAGS / "robot_localization_husky"
TB3 = BAGS / "fuse_turtlebot3_sim"


@dataclass(frozen=True)
class Cloud:
    """The cloud side shared by a module's tests: a router and an uplink behind it."""

    router: str
    bootstrap: str
    registry_url: str
    registrations: str
    dead_letter: str


def uplink_config(
    cloud_router: str, bootstrap: str, registry_url: str, *, suffix: str, message_max_bytes: int = 1_000_000
) -> UplinkConfig:
    return UplinkConfig.model_validate(
        {
            "kafka": {"bootstrap_servers": bootstrap, "message_max_bytes": message_max_bytes},
            "registry": {"url": registry_url},
            "zenoh": {"mode": "client", "connect": [cloud_router]},
            "topics": {"dead_letter": f"e2e.dead-letter.{suffix}", "registrations": f"e2e.robots.{suffix}"},
        }
    )


@contextmanager
def cloud(bootstrap: str, registry_url: str, *, message_max_bytes: int = 1_000_000) -> Iterator[Cloud]:
    suffix = uuid.uuid4().hex[:8]
    with ZenohRouter() as router:
        config = uplink_config(
            router.endpoint, bootstrap, registry_url, suffix=suffix, message_max_bytes=message_max_bytes
        )
        with Uplink(config):
            yield Cloud(
                router.endpoint,
                bootstrap,
                registry_url,
                config.topics.registrations,
                config.topics.dead_letter,
            )


def edge_config(
    spool: Path,
    site_router: str,
    cloud_: Cloud,
    *,
    site: str,
    robot_types: Mapping[str, Any] | None = None,
    mappings: Sequence[Mapping[str, Any]] = (),
    **extra: Any,
) -> EdgeConfig:
    data: dict[str, Any] = {
        "site": site,
        "edge_id": "edge-1",
        "zenoh": {"mode": "client", "connect": [site_router]},
        "robot_types": dict(robot_types or {}),
        "mappings": list(mappings),
        "spool": {"dir": str(spool), "segment_bytes": "4MiB", "max_bytes": "64MiB"},
        "registration": {"grace_period": "1s"},
        # one batch in flight per stream: the uplink runs batches on a worker pool, so two batches
        # of a stream in flight at once may reach Kafka in either order (see docs/edge.md)
        "wan": {
            "linger": "5ms",
            "ack_timeout": "20s",
            "retry_backoff_min": "50ms",
            "retry_backoff_max": "1s",
            "max_in_flight": 1,
        },
        "topics": {"dead_letter": cloud_.dead_letter, "registrations": cloud_.registrations},
        # an edge in the test process reports the whole test runner's memory (500 MB and more
        # with Kafka clients, browsers' drivers and several edges): a bound that fits it keeps
        # its health about the site, not the runner (process edges keep the default bound)
        "intake": {"max_bytes": "768MiB"},
    }
    data.update(extra)
    return EdgeConfig.model_validate(data)


def isolating_cloud_router() -> ZenohRouter:
    """A cloud router that lets only ``fleetlink/**`` cross, as the shipped dev template does
    (``deploy/zenoh/cloud-router-dev.json5``): each site's raw ROS traffic stays on the site, so
    robots of different sites may share names. (The bare cloud router of the other tests passes
    everything: their sites' robots see each other, which some of them test.)"""
    template = render_router_config(DEPLOY / "zenoh" / "cloud-router-dev.json5", listen=[])
    return ZenohRouter(extra={"access_control": json.loads(template.get_json("access_control"))})


@contextmanager
def site(cloud_: Cloud) -> Iterator[ZenohRouter]:
    """A site's router, joined to the cloud router."""
    with ZenohRouter(connect=(cloud_.router,)) as router:
        yield router


def replayer(bag: Path, robot: str, router: str, topics: Sequence[str]) -> BagReplayer:
    """A robot replaying ``topics`` of ``bag`` as fast as the network takes them."""
    return BagReplayer(bag, robot, config=zenoh_peer_config(router), rate=0, topics=list(topics))


def bag_messages(bag: Path, topic: str) -> list[bytes]:
    with Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [bytes(raw) for _, _, raw in reader.messages(connections=conns)]


def wait_spooled_and_acked(
    agent: EdgeAgent,
    records: int,
    timeout: float,
    *,
    uplink_dead_letters: int = 0,
    stream_name: str = "durable",
) -> None:
    """Wait until the stream (``durable``: the spool, ``memory``: best effort) took at least
    ``records`` and the uplink acked them all; then check that the uplink dead-lettered exactly
    ``uplink_dead_letters`` of them."""

    def done() -> bool:
        stream = agent.snapshot()["streams"][stream_name]
        buffer = stream["buffer"]
        return bool(buffer["appended"] >= records and buffer["depth"] == 0)

    try:
        wait_until(done, timeout, interval=0.1, message=f"{records} records spooled and acknowledged")
    except AssertionError as exc:
        raise AssertionError(f"{exc}; edge: {edge_brief(agent)}") from None
    sender = agent.snapshot()["streams"][stream_name]["sender"]
    assert sender["records_dead_lettered"] == uplink_dead_letters, sender


def edge_brief(agent: EdgeAgent, *extra: str) -> str:
    """The edge's counters along the data path (and ``extra`` snapshot keys), as JSON: what a
    test that waited in vain prints to say where the records stopped."""
    snap = agent.snapshot()
    keys = ("intake", "processor", "streams", "subscriptions", *extra)
    return json.dumps({k: snap.get(k) for k in keys}, default=str)


def wait_received(agent: EdgeAgent, samples: int, timeout: float) -> None:
    """Wait until the edge's processor has taken ``samples`` samples (with the subscriptions'
    counters in the failure message)."""

    def done() -> bool:
        return bool(agent.snapshot()["processor"]["samples"] >= samples)

    try:
        wait_until(done, timeout, interval=0.05, message=f"{samples} samples received")
    except AssertionError as exc:
        snap = agent.snapshot()
        raise AssertionError(
            f"{exc}; processor {snap['processor']}, intake {snap['intake']}, "
            f"subscriptions {json.dumps(snap['subscriptions'])}"
        ) from None


def counter(agent: EdgeAgent, mapping: str, name: str) -> int:
    """One of a mapping's counters (0 before its first sample)."""
    return int(agent.snapshot().get("mappings", {}).get(mapping, {}).get(name, 0))


class TopicReader:
    """Reads Kafka topics from the beginning, decoding values with the stock AvroDeserializer."""

    def __init__(self, bootstrap: str, registry_url: str) -> None:
        self.bootstrap = bootstrap
        self.deserializer = AvroDeserializer(SchemaRegistryClient({"url": registry_url}))

    def read(self, topic: str, count: int, timeout: float = 30.0) -> list[Message]:
        """The first ``count`` records of a one-partition topic, plus whatever follows within a
        second (so a test can see duplicates)."""
        out = self.read_until(topic, lambda ms: len(ms) >= count, timeout, what=f"{count} records on {topic}")
        return out + self.consume(topic, len(out), lambda ms: False, 1.0)

    def read_until(
        self, topic: str, done: Callable[[list[Message]], bool], timeout: float = 30.0, what: str = ""
    ) -> list[Message]:
        """Records of a one-partition topic from the beginning until ``done(records)`` holds."""
        out = self.consume(topic, 0, done, timeout)
        if not done(out):
            raise AssertionError(
                f"timed out after {timeout:.0f}s waiting for {what or topic} (got {len(out)} records)"
            )
        return out

    def consume(
        self, topic: str, offset: int, done: Callable[[list[Message]], bool], timeout: float
    ) -> list[Message]:
        """Consume from ``offset`` until ``done`` or the deadline; a consumer that makes no
        progress for a while (stale metadata of a topic created moments ago) is replaced."""
        out: list[Message] = []
        deadline = time.monotonic() + timeout
        while not done(out) and time.monotonic() < deadline:
            consumer = Consumer(
                {
                    "bootstrap.servers": self.bootstrap,
                    "group.id": f"e2e-{uuid.uuid4().hex}",
                    "enable.auto.commit": False,
                    "topic.metadata.refresh.interval.ms": 500,
                }
            )
            try:
                consumer.assign([TopicPartition(topic, 0, offset + len(out))])
                progress = time.monotonic()
                while not done(out) and time.monotonic() < deadline and time.monotonic() - progress < 8:
                    batch = [m for m in consumer.consume(1000, timeout=0.2) if m.error() is None]
                    if batch:
                        out.extend(batch)
                        progress = time.monotonic()
            finally:
                consumer.close()
        return out

    def value(self, msg: Message) -> Any:
        topic = msg.topic()
        if topic is None:
            raise AssertionError("a record without a topic")
        context = SerializationContext(topic, MessageField.VALUE)
        return on_a_live_connection(lambda: self.deserializer(msg.value(), context))


def headers(msg: Message) -> dict[str, str]:
    return {k: (v or b"").decode("utf-8", "replace") for k, v in (msg.headers() or [])}


def by_key(msgs: Sequence[Message]) -> dict[str, list[Message]]:
    out: dict[str, list[Message]] = {}
    for msg in msgs:
        out.setdefault((msg.key() or b"").decode(), []).append(msg)
    return out


def seqs(msgs: Sequence[Message]) -> list[int]:
    return [int(headers(m)["fleetlink.seq"]) for m in msgs]


def unique_site() -> str:
    return f"site-{uuid.uuid4().hex[:8]}"


Check = Callable[[], bool]
