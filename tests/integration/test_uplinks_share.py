"""Several uplinks share a fleet's load: each edge's stream goes to one uplink by name (found by
probing), and when that uplink stops its edges move to the others, losing nothing.

Real Kafka, registry, a cloud router, two uplinks and four sites (a router and an edge each).
Each site's robot is ``/tb4_01``: the cloud router keeps each site's ROS traffic on the site,
as the shipped one does (with a bare one, every edge would take every site's robot).
"""

from __future__ import annotations

import uuid
from contextlib import ExitStack
from functools import partial
from pathlib import Path

from fleetlink.edge.agent import EdgeAgent
from fleetlink.edge.runtime.uplinks import pick
from fleetlink.roswire import cdr
from fleetlink.roswire.node import RosNode
from fleetlink.schemas.typestore import load_typestore
from fleetlink.uplink.service import Uplink
from fleetlink.wire import ingest_key
from tests.helpers import wait_until, zenoh_peer_config
from tests.integration.e2e_stack import (
    Cloud,
    TopicReader,
    edge_config,
    isolating_cloud_router,
    seqs,
    site,
    uplink_config,
)

STRING = "std_msgs/msg/String"
SITES = 4


def sites_for(uplinks: tuple[str, str], tag: str) -> list[str]:
    """``SITES`` site names whose durable streams do not all go to one uplink."""
    n = 0
    while True:
        names = [f"share-{tag}-{n + i}" for i in range(SITES)]
        chosen = {pick(f"{ingest_key(s, 'edge-1')}|at_least_once", uplinks) for s in names}
        if chosen == set(uplinks):
            return names
        n += SITES


def test_two_uplinks_share_the_sites_and_one_takes_over_when_the_other_stops(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    tag = uuid.uuid4().hex[:8]
    reader = TopicReader(kafka_bootstrap, schema_registry_url)
    with isolating_cloud_router() as cloud_router, ExitStack() as stack:  # every robot is tb4_01
        base = uplink_config(cloud_router.endpoint, kafka_bootstrap, schema_registry_url, suffix=tag)
        ids = (f"share-a-{tag}", f"share-b-{tag}")
        a = stack.enter_context(Uplink(base.model_copy(update={"id": ids[0]})))
        b = stack.enter_context(Uplink(base.model_copy(update={"id": ids[1]})))
        cloud_ = Cloud(
            cloud_router.endpoint,
            kafka_bootstrap,
            schema_registry_url,
            base.topics.registrations,
            base.topics.dead_letter,
        )
        names = sites_for(ids, tag)
        topics = {s: f"fleet.share.{s}" for s in names}
        agents, publishers = {}, {}
        for s in names:
            router = stack.enter_context(site(cloud_))
            mapping = {"name": "chat", "from": "/tb4_01/chatter", "to": topics[s], "key": "tb4_01"}
            config = edge_config(tmp_path / s, router.endpoint, cloud_, site=s, mappings=[mapping])
            agents[s] = stack.enter_context(EdgeAgent(config))
            robot = RosNode(
                "chat",
                "/tb4_01",
                config=zenoh_peer_config(router.endpoint),
                typestore=load_typestore("jazzy"),
            )
            node = stack.enter_context(robot)
            publishers[s] = node.create_publisher("/tb4_01/chatter", STRING, congestion="block")
        for s in names:
            wait_until(publishers[s].has_subscribers, 10, message=f"edge of {s} subscribed")

        def publish(start: int, count: int) -> None:
            for s in names:
                for n in range(start, start + count):
                    publishers[s].publish_cdr(cdr.encode_string(f"{s} {n}"))

        def buffer(s: str) -> dict[str, int]:
            stats: dict[str, int] = agents[s].snapshot()["streams"]["durable"]["buffer"]
            return stats

        others: dict[str, int] = {}  # records in each stream that are not samples (registrations)

        def acked(total: int) -> None:
            """Every sample published so far spooled and acknowledged (the spool empty). A count of
            acknowledged records would count a batch sent twice, and the registration records."""
            for s in names:
                wait_until(
                    partial(
                        lambda s: (b := buffer(s))["appended"] >= others[s] + total and b["depth"] == 0, s
                    ),
                    30,
                    message=f"{total} samples of {s} acknowledged",
                )

        def found(s: str) -> bool:
            return bool(agents[s].snapshot().get("uplinks") == sorted(ids))

        publish(0, 1)  # each edge's first send probes the uplinks
        for s in names:
            samples = partial(lambda s: agents[s].snapshot()["processor"]["samples"] >= 1, s)
            wait_until(samples, 30, message=f"the first sample of {s} taken")
            wait_until(partial(lambda s: buffer(s)["depth"] == 0, s), 30, message=f"{s} acknowledged")
            others[s] = buffer(s)["appended"] - 1
        acked(1)
        for s in names:
            wait_until(partial(found, s), 10, message=f"the edge of {s} found both uplinks")
        before = (a.stats.batches, b.stats.batches)
        publish(1, 49)
        acked(50)
        assert a.stats.batches > before[0]  # both uplinks took batches ...
        assert b.stats.batches > before[1]
        a.stop()  # ... and the sites of the one that stops move to the other
        publish(50, 50)
        acked(100)
    for s in names:
        records = reader.read_until(
            topics[s], lambda ms: set(seqs(ms)) >= set(range(1, 101)), what=f"samples 1..100 of {s}"
        )
        assert sorted(set(seqs(records))) == list(range(1, 101)), s  # lost 0 (a batch the stopped
        # uplink wrote but could not acknowledge is written again: at least once)
        assert {reader.value(m)["data"].split()[0] for m in records} == {s}  # its own robot's alone
