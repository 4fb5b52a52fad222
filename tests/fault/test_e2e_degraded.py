"""Robot -> Kafka rows of the reliability matrix where a part hangs or crawls instead of dying.

Row 3  Kafka frozen:   SIGSTOP the broker mid-stream for longer than the edge's ack timeout,
                       then SIGCONT; the edge keeps spooling and re-sends the batch that timed
                       out; lost 0, and every duplicate is explained by a retried batch.
Row 5  flapping WAN:   the relay alternates between swallowing everything and passing for a
                       few seconds; lost 0, one warning per outage, retries bounded.
Row 15 edge stalled:   SIGSTOP the edge for 2 s while the robot publishes; whatever does not
                       reach Kafka is counted by the edge (intake drops, sequence gaps at the
                       subscriber): nothing disappears silently.
Row 16 registry down:  the uplink's registry refuses connections when a new topic's schema must
                       be registered; its batches are answered ``error`` and stay in the edge's
                       spool; once the registry is back everything lands; lost 0.
Row 6  slow WAN:       the relay holds every chunk 0.2 s each way; the robot's rate exceeds what
                       the link carries, so the backlog grows in the spool, not in front of
                       Zenoh: no sample dropped at the intake or missing at the subscriber.
"""

from __future__ import annotations

import math
import signal
import time
from pathlib import Path
from typing import Any

import pytest

from fleetlink.localstack.kafka import KafkaBroker
from tests.fault import e2e_processes
from tests.fault.e2e_processes import (
    WITH_EXACTLY_ONCE,
    Bed,
    Count,
    Generator,
    bed,
    generate,
    spool_depth,
    streaming,
    tally,
)
from tests.integration.e2e_stack import TopicReader

pytestmark = pytest.mark.usefixtures("wan_profile")


def sender(b: Bed) -> dict[str, Any]:
    stats: dict[str, Any] = b.durable().get("sender", {})
    return stats


def check(result: Count, retried: int) -> None:
    """Nothing lost or foreign; each duplicate belongs to a batch the edge sent again."""
    assert result.lost == [], str(result)
    assert result.unexpected == 0, str(result)
    profile = e2e_processes.PROFILE
    allowed = 0 if profile.delivery == "exactly_once" else profile.batch * retried
    assert result.duplicated <= allowed, f"{result}; {retried} batch(es) retried"


def test_kafka_frozen_longer_than_the_ack_timeout(
    own_kafka: KafkaBroker, schema_registry_url: str, tmp_path: Path
) -> None:
    reader = TopicReader(own_kafka.bootstrap, schema_registry_url)
    with streaming(tmp_path, own_kafka.bootstrap, schema_registry_url, ack_timeout="2s") as (b, gen):
        generate(b, gen, 600)
        b.wait(lambda: b.durable().get("buffer", {}).get("acked", 0) > 0, 20, "records reach Kafka")
        before = sender(b).get("batches_retried", 0)  # e.g. a first batch before the uplink was up
        own_kafka.process.signal(signal.SIGSTOP)
        frozen_at = time.monotonic()
        try:
            b.wait(
                lambda: sender(b).get("batches_retried", 0) > before,
                15,
                "the edge times out on the frozen broker and re-sends",
            )
            generate(b, gen, 800)
            spool_depth(b, 400, "the edge keeps spooling")
        finally:
            own_kafka.process.signal(signal.SIGCONT)
        frozen_s = time.monotonic() - frozen_at
        generate(b, gen, 300)
        sent = gen.pause()
        b.wait_drained(sent, 60)
        retried = sender(b)["batches_retried"]
    check(tally(reader, b, sent, f", Kafka frozen {frozen_s:.1f} s, {retried} retried"), retried)
    # a retry waits for its ack timeout (2 s) or its backoff: a frozen broker is not hammered
    assert retried <= math.ceil(frozen_s / 2.0) + 3


@pytest.mark.parametrize("wan_profile", WITH_EXACTLY_ONCE, ids=lambda p: p.name, indirect=True)
def test_flapping_wan(kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path) -> None:
    reader = TopicReader(kafka_bootstrap, schema_registry_url)
    with streaming(tmp_path, kafka_bootstrap, schema_registry_url, ack_timeout="1s") as (b, gen):
        generate(b, gen, 400)
        began = time.monotonic()
        for _ in range(4):  # cut for 600 records (1.5 s at 400 msg/s), up for as many, four times
            b.relay.set_mode("blackhole")
            generate(b, gen, 600)
            b.relay.set_mode("pass")
            generate(b, gen, 600)
        flapped_s = time.monotonic() - began
        b.assert_memory_bounded()
        generate(b, gen, 200)
        sent = gen.pause()
        b.wait_drained(sent, 60)
        stats = sender(b)
        assert b.edge is not None
        warnings = b.edge.log_lines("batch not acknowledged")
    retried, outages = stats["batches_retried"], stats["outages"]
    what = f" over {flapped_s:.1f} s of flapping, {outages} outage(s), {retried} retried"
    check(tally(reader, b, sent, what), retried)
    assert 1 <= outages <= 8  # each cut is one outage (a heal may break Zenoh's stream once more)
    assert warnings == outages  # one warning per outage, no storm
    # backoff between attempts (100 ms doubling to 1 s) and the ack timeout bound the retries
    assert retried <= flapped_s / 0.1


def test_slow_wan_backlog_grows_in_the_spool_not_in_front_of_zenoh(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    reader = TopicReader(kafka_bootstrap, schema_registry_url)
    with streaming(tmp_path, kafka_bootstrap, schema_registry_url, rate=600.0) as (b, gen):
        generate(b, gen, 300)
        b.relay.set_mode("delay", 0.2)  # ~0.4 s a round trip
        generate(b, gen, 2400)
        # one batch of 100 per round trip cannot keep up with 600/s: the backlog grows; with the
        # defaults (4 x 2,000) the link keeps up and holds what a round trip takes (~240)
        profile = e2e_processes.PROFILE
        expected = 500 if profile.window / 0.4 < 600 else 120
        backlog = spool_depth(b, expected, "the backlog waits in the spool")
        b.assert_memory_bounded()
        b.relay.set_mode("pass")
        sent = gen.pause()
        b.wait_drained(sent, 60)
        stats = b.stats()
    check(
        tally(reader, b, sent, f", {backlog} in the spool at the slowest"),
        stats["streams"]["durable"]["sender"]["batches_retried"],
    )
    assert stats["intake"]["dropped"] == 0
    chatter = stats["subscriptions"]["/tb4_01/chatter"]
    assert (chatter["missing"], chatter["received"]) == (0, sent)


def test_registry_down_when_a_new_topic_needs_its_schema(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    reader = TopicReader(kafka_bootstrap, schema_registry_url)
    with bed(tmp_path, kafka_bootstrap, schema_registry_url, registry_relay=True) as b:
        registry = b.registry_relay
        assert registry is not None
        b.start_uplink()
        b.start_edge()
        gen = Generator(b.site.endpoint)  # the robot joins: its registration event is the first record
        try:
            b.wait(
                lambda: b.durable().get("buffer", {}).get("acked", 0) >= 1,
                30,
                "the registration event in Kafka (the registry is reachable)",
            )
            registry.set_mode("refuse")
            gen.wait_subscribed()
            gen.start()
            b.wait(
                lambda: sender(b).get("batches_retried", 0) >= 2,
                15,
                "batches answered 'error' while the registry is down, and sent again",
            )
            generate(b, gen, 400)
            spool_depth(b, 300, "the records wait in the spool")
            assert reader.consume(b.topic, 0, lambda ms: False, 0.5) == []  # nothing half-produced
            registry.set_mode("pass")
            generate(b, gen, 200)
            sent = gen.pause()
            b.wait_drained(sent, 40)
            retried = sender(b)["batches_retried"]
            assert b.uplink is not None
            errors = b.uplink.log_lines("not fully delivered")
        finally:
            gen.close()
    check(tally(reader, b, sent, f", registry down then back, {retried} retried"), retried)
    assert errors >= 1  # the uplink said why


def test_a_stalled_edge_loses_nothing_silently(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    reader = TopicReader(kafka_bootstrap, schema_registry_url)
    with streaming(tmp_path, kafka_bootstrap, schema_registry_url) as (b, gen):
        generate(b, gen, 400)
        edge = b.edge
        assert edge is not None
        edge.pause()
        try:
            generate(b, gen, 800)  # 2 s of publishing at 400 msg/s into a stopped edge
        finally:
            edge.resume()
        generate(b, gen, 400)
        sent = gen.pause()

        def counted() -> int:
            stats = b.stats()
            chatter = stats.get("subscriptions", {}).get("/tb4_01/chatter", {})
            return int(stats.get("intake", {}).get("dropped", 0)) + int(chatter.get("missing", 0))

        b.wait(
            lambda: (
                b.stats().get("processor", {}).get("samples", 0) + counted() >= sent
                and b.durable().get("buffer", {}).get("depth") == 0
            ),
            40,
            "everything processed or counted",
        )
        accounted = counted()
        b.assert_memory_bounded()
    result = tally(reader, b, sent, f" with the edge stopped 2 s; {accounted} counted as lost by the edge")
    assert len(result.lost) == accounted, str(result)
    assert (result.unexpected, result.duplicated) == (0, 0), str(result)
