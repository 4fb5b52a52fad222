"""Command rows of the reliability matrix (docs/reliability.md), with real services.

Row 23  malformed command records (garbage, wrong magic byte, unknown schema id, a body the
        schema cannot read, a tombstone): command dead-letter topic with the raw bytes and the
        reason, offsets committed, nothing sent to any robot; the next good command flows.
Row 24  the uplink (a real ``fleetlink uplink run`` process) is killed with SIGKILL after the
        repeater applied a command but before the reply reached it (the WAN relay delays the
        reply): a second uplink in the same consumer group gets the record again, forwards it,
        the repeater answers ``duplicate``; the command is applied once (no second schedule, no
        extra publish, no status but "delivered"), and the offset is committed.
Row 25  a repeater stopped while its command's robot is offline and restarted after the lease:
        the command is not replayed, and is recorded as expired.
Also    a repeater restarted within the lease resumes repeating from its journal; cutting the
        WAN (relay blackhole) leaves local repeats running until the lease ends, and the
        dead-man stops them early when configured; the statuses reach Kafka after the heal.
"""

from __future__ import annotations

import signal
import struct
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import yaml
from confluent_kafka import Consumer, TopicPartition

from fleetlink.repeater.service import Repeater
from fleetlink.uplink.config import UplinkConfig
from tests.helpers import wait_until
from tests.integration.test_commands_harness import (
    GREEN,
    RED,
    CommandProducer,
    LedLog,
    TopicLog,
    Wan,
    create_topics,
    distinct,
    fleet,
    irobot_store,
    lightring_bed,
    lightring_mapping,
    repeater_config,
    running_uplink,
    uid,
    uplink_config,
    wait_repeater_sees,
)

ROOT = Path(__file__).resolve().parents[2]


def committed(bootstrap: str, group: str, topic: str) -> int:
    consumer = Consumer({"bootstrap.servers": bootstrap, "group.id": group, "enable.auto.commit": False})
    try:
        offset: int = consumer.committed([TopicPartition(topic, 0)], timeout=10)[0].offset
        return offset
    finally:
        consumer.close()


@contextmanager
def uplink_process(config: UplinkConfig, path: Path) -> Iterator[subprocess.Popen[bytes]]:
    path.write_text(yaml.safe_dump(config.model_dump(mode="json", by_alias=True, exclude_none=True)))
    with path.with_suffix(".log").open("wb") as log:
        argv = [sys.executable, "-m", "fleetlink.cli", "-v", "uplink", "run", "-c", str(path)]
        proc = subprocess.Popen(argv, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5)


def test_row23_malformed_commands_are_dead_lettered_and_nothing_is_sent(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    ts = irobot_store()
    run = uid()
    topic = f"cmd.lightring.{run}"
    producer = CommandProducer(kafka_bootstrap, schema_registry_url, ts)
    good = producer.value(topic, GREEN)  # registers the schema; its id frames the bad body below
    schema_id = struct.unpack(">I", good[1:5])[0]
    bad = {
        "garbage": b"this is not a command",
        "wrong magic byte": b"\x01" + good[1:],
        "unknown schema id": b"\x00" + struct.pack(">I", 987_654) + good[5:],
        "body the schema cannot read": b"\x00" + struct.pack(">I", schema_id) + good[5:12],
        "trailing bytes": good + b"\x00\x00",
    }
    leds = LedLog()
    with Wan() as wan:
        site = wan.add_site("site-a")
        config = uplink_config(
            kafka_bootstrap, schema_registry_url, wan.cloud.endpoint, [lightring_mapping(topic)], suffix=run
        )
        create_topics(kafka_bootstrap, topic)
        for raw in bad.values():
            producer.send(topic, "tb4_01", raw_value=raw)
        producer.send(topic, "tb4_01", raw_value=b"")  # empty value
        producer.send(topic, "tb4_02", GREEN, command_id=f"good-{run}")
        with (
            Repeater(repeater_config(site, tmp_path / "state")) as rep,
            fleet(site, ts, leds) as robots,
            TopicLog(
                kafka_bootstrap, schema_registry_url, config.topics.command_dead_letter, avro=False
            ) as dlq,
            running_uplink(config) as uplink,
        ):
            robots.add_robot("tb4_01")
            robots.add_robot("tb4_02")
            router = uplink.commands
            assert router is not None
            wait_until(
                lambda: leds.first("tb4_02", "green") is not None,
                timeout=15,
                message="the good command after the bad ones is delivered",
            )
            wait_until(lambda: len(dlq.records) == len(bad) + 1, timeout=10, message="dead letters")
            wait_until(
                lambda: committed(kafka_bootstrap, router.group_id, topic) == len(bad) + 2,
                timeout=10,
                message="every offset committed",
            )
            by_value = {r["value"] or b"": r for r in dlq.records}
            for what, raw in bad.items():
                record = by_value[raw]  # the raw bytes, unchanged
                headers = record["headers"]
                assert record["key"] == b"tb4_01", what
                assert headers["fleetlink.dlq.stage"] == b"command-decode", what
                assert headers["fleetlink.dlq.topic"] == topic.encode(), what
            reasons = sorted(r["headers"]["fleetlink.dlq.reason"].decode() for r in dlq.records)
            assert any("magic byte 0x01" in r for r in reasons)
            assert any("unknown schema id 987654" in r for r in reasons)
            assert any("left over after the Avro record" in r for r in reasons)
            assert any("does not match schema id" in r for r in reasons)
            # nothing of it reached a site, let alone a robot
            assert (rep.stats.applied, rep.stats.malformed, rep.stats.rejected) == (1, 0, 0)
            assert rep.stats.by_topic["/tb4_01/cmd_lightring"] == 0
            assert leds.count("tb4_01") == 0
            assert router.stats.dead_lettered == len(bad) + 1


def test_row24_command_redelivered_after_uplink_kill_is_applied_once(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    ts = irobot_store()
    run = uid()
    topic = f"cmd.lightring.{run}"
    producer = CommandProducer(kafka_bootstrap, schema_registry_url, ts)
    leds = LedLog()
    with Wan() as wan:
        site = wan.add_site("site-a")
        config = uplink_config(
            kafka_bootstrap,
            schema_registry_url,
            wan.cloud.endpoint,
            # a lease that outlasts the test: its steps (two uplinks starting, a group rebalance
            # after a kill) take 20-40 s on a loaded machine, and the repeats must not end before
            [lightring_mapping(topic, period="1s", lease="120s")],
            suffix=run,
        )
        # the killed uplink's group membership must time out before the second one gets the partition
        kafka = config.kafka.model_copy(
            update={"consumer_overrides": {"session.timeout.ms": 6000, "heartbeat.interval.ms": 1000}}
        )
        config = config.model_copy(update={"kafka": kafka})
        create_topics(kafka_bootstrap, topic)
        with (
            Repeater(repeater_config(site, tmp_path / "state")) as rep,
            fleet(site, ts, leds) as robots,
            TopicLog(kafka_bootstrap, schema_registry_url, config.topics.command_status) as status,
        ):
            robots.add_robot("tb4_01")
            wait_repeater_sees(rep, "/tb4_01/cmd_lightring")
            producer.send(topic, "tb4_01", RED, command_id=f"once-{run}")
            # the repeater's reply takes a while (under the uplink's 5 s query timeout): the kill
            # below lands between forwarding and commit even when this process is held up
            site.relay.set_mode("delay", delay_s=4.0)
            with uplink_process(config, tmp_path / "uplink1.yaml") as first:
                wait_until(lambda: rep.stats.applied == 1, timeout=30, message="first uplink forwarded it")
                first.send_signal(signal.SIGKILL)  # between forwarding and commit
                first.wait(10)
            assert committed(kafka_bootstrap, f"uplink-{run}.commands", topic) < 0  # nothing committed
            site.relay.set_mode("pass")
            wait_until(lambda: leds.count("tb4_01", "red") >= 2, timeout=10, message="repeating locally")
            with uplink_process(config, tmp_path / "uplink2.yaml"):
                wait_until(
                    lambda: rep.stats.duplicates >= 1,
                    timeout=30,
                    message="the second uplink re-delivered the command",
                )
                wait_until(
                    lambda: committed(kafka_bootstrap, f"uplink-{run}.commands", topic) == 1,
                    timeout=15,
                    message="offset committed after the duplicate reply",
                )
                wait_until(
                    lambda: "delivered" in status.statuses(f"once-{run}"),
                    timeout=15,
                    message="delivered status",
                )
                marker = leds.count("tb4_01")
                wait_until(lambda: leds.count("tb4_01") >= marker + 2, timeout=10, message="more repeats")
            assert rep.stats.applied == 1
            # status records are at-least-once: the slowed link may have made the repeater send its
            # batch twice, but the command reached "delivered" once and nothing else happened to it
            assert set(status.statuses(f"once-{run}")) == {"delivered"}
            # one schedule, once a second: the re-delivery caused no extra publish (counted over the
            # span of the repeats, so one late tick, and the next one sooner to keep the rhythm, is no
            # extra). The repeats keep the rhythm of the command's arrival; the first publish, by a
            # publisher declared for it a moment before, may reach the robot up to half a second
            # late on a loaded machine, so it does not start the span.
            times = [t for t, _ in leds.of("tb4_01")]
            repeats = times[1:]
            assert len(repeats) - 1 <= (repeats[-1] - repeats[0]) / 1.0 + 0.5, times


def test_row25_repeater_restarted_after_the_lease_does_not_replay(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    lease = 3.0
    state = tmp_path / "state"
    with lightring_bed(kafka_bootstrap, schema_registry_url, period="500ms", lease=f"{lease}s") as bed:
        ts, run, topic, producer, leds, site, config = (
            bed.ts,
            bed.run,
            bed.topic,
            bed.producer,
            bed.leds,
            bed.site,
            bed.config,
        )
        with (
            TopicLog(kafka_bootstrap, schema_registry_url, config.topics.command_status) as status,
            running_uplink(config) as uplink,
            fleet(site, ts, leds) as robots,
        ):
            router = uplink.commands
            assert router is not None
            with Repeater(repeater_config(site, state)) as rep:
                sent = producer.send(topic, "tb4_01", RED, command_id=f"stale-{run}")
                wait_until(lambda: rep.stats.applied == 1, timeout=10, message="applied, robot offline")
                # the repeater counts a command applied before its answer leaves: stopped at once, the
                # uplink would hear nothing, retry until the lease ends and report it expired itself
                wait_until(lambda: router.stats.settled == 1, timeout=10, message="the uplink got the answer")
            assert leds.count("tb4_01") == 0
            wait_until(
                lambda: time.time() > sent + lease + 0.5,
                timeout=lease + 5,
                message="the lease ended while the repeater was down",
            )
            robots.add_robot("tb4_01")  # the robot is back
            robots.add_robot("tb4_02")
            with Repeater(repeater_config(site, state)) as rep:
                wait_repeater_sees(rep, "/tb4_01/cmd_lightring")
                wait_until(
                    lambda: "expired" in status.statuses(f"stale-{run}"),
                    timeout=10,
                    message="recorded as expired",
                )
                expired = next(v for v in status.values() if v["command_id"] == f"stale-{run}")
                assert expired["detail"] == "lease ended while the repeater was down"
                # positive control: a fresh command flows through the same repeater meanwhile
                producer.send(topic, "tb4_02", GREEN, command_id=f"fresh-{run}")
                wait_until(lambda: leds.count("tb4_02", "green") >= 3, timeout=10, message="fresh repeats")
                assert leds.count("tb4_01") == 0
                assert rep.stats.by_topic["/tb4_01/cmd_lightring"] == 0
                assert rep.schedule.active()[0].command_id == f"fresh-{run}"
            assert status.statuses(f"stale-{run}") == ["expired"]


def test_repeater_restarted_within_the_lease_resumes_without_reapplying(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    state = tmp_path / "state"
    with lightring_bed(kafka_bootstrap, schema_registry_url, period="500ms", lease="20s") as bed:
        ts, run, topic, producer, leds, site, config = (
            bed.ts,
            bed.run,
            bed.topic,
            bed.producer,
            bed.leds,
            bed.site,
            bed.config,
        )
        with (
            TopicLog(kafka_bootstrap, schema_registry_url, config.topics.command_status) as status,
            fleet(site, ts, leds) as robots,
            running_uplink(config),
        ):
            robots.add_robot("tb4_01")
            with Repeater(repeater_config(site, state)) as rep:
                wait_repeater_sees(rep, "/tb4_01/cmd_lightring")
                producer.send(topic, "tb4_01", RED, command_id=f"keep-{run}")
                wait_until(lambda: leds.count("tb4_01", "red") >= 2, timeout=10, message="repeating")
                wait_until(
                    lambda: status.statuses(f"keep-{run}") == ["delivered"], timeout=10, message="delivered"
                )
            stopped_at = leds.count("tb4_01")
            with Repeater(repeater_config(site, state)) as rep:
                wait_until(
                    lambda: leds.count("tb4_01") >= stopped_at + 3,
                    timeout=10,
                    message="repeats resumed from the journal",
                )
                assert rep.stats.applied == 0  # resumed, not re-applied
                assert [c.command_id for c in rep.schedule.active()] == [f"keep-{run}"]
            assert status.statuses(f"keep-{run}") == ["delivered"]  # not twice


def test_wan_cut_local_repeats_stop_when_the_lease_runs_out(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    lease = 8.0  # the command reaches the robot (1-3 s on a loaded machine), then a cut of some seconds
    with lightring_bed(kafka_bootstrap, schema_registry_url, period="500ms", lease=f"{lease}s") as bed:
        ts, run, topic, producer, leds, site, config = (
            bed.ts,
            bed.run,
            bed.topic,
            bed.producer,
            bed.leds,
            bed.site,
            bed.config,
        )
        with (
            TopicLog(kafka_bootstrap, schema_registry_url, config.topics.command_status) as status,
            fleet(site, ts, leds) as robots,
            running_uplink(config),
            Repeater(repeater_config(site, tmp_path / "state")) as rep,
        ):
            robots.add_robot("tb4_01")
            wait_repeater_sees(rep, "/tb4_01/cmd_lightring")
            sent = producer.send(topic, "tb4_01", RED, command_id=f"cut-{run}")
            wait_until(lambda: leds.count("tb4_01", "red") >= 1, timeout=5, message="delivered")
            site.relay.set_mode("blackhole")
            cut_at = time.time()
            wait_until(lambda: rep.schedule.link_lost_since is not None, timeout=5, message="link loss seen")
            wait_until(lambda: not rep.schedule.active(), timeout=lease + 3, message="command ended")
            # the schedule ends a command under the lock the publishes hold: none is under way now
            publishes = rep.stats.publishes
            during = [t for t, _ in leds.of("tb4_01") if t > cut_at]
            assert len(during) >= 3  # the site kept repeating on its own while the WAN was down
            last = leds.last("tb4_01")
            assert last is not None
            assert last <= sent + lease + 0.3  # ... and stopped when the lease ran out
            site.relay.set_mode("pass")
            # at-least-once: a batch whose answer the cut swallowed comes again. The bytes the
            # relay swallowed broke the Zenoh stream of the WAN link, which may have to time out
            # and reconnect first. The site's statuses come in its order; when the cut also
            # swallowed the repeater's "applied" reply, the uplink reports the command expired
            # on its own (site "") once the lease ends, which may land before the site's.
            try:
                wait_until(
                    lambda: (
                        distinct(status.statuses(f"cut-{run}", site=site.name)) == ["delivered", "expired"]
                    ),
                    timeout=60,
                    message="statuses reach Kafka after the heal",
                )
            except AssertionError as exc:
                raise AssertionError(
                    f"{exc}; in Kafka: {status.statuses(f'cut-{run}')}, still pending at "
                    f"the repeater: {rep.pending_statuses()}"
                ) from None
            assert set(status.statuses(f"cut-{run}", site="")) <= {"expired"}
            # nothing published after the lease, the heal included (the robot logs arrival times:
            # a repeat sent just before the lease ran out may land after ``last`` was read above)
            assert rep.stats.publishes == publishes


def test_wan_cut_dead_man_stops_a_long_lease_early(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    with lightring_bed(kafka_bootstrap, schema_registry_url, period="500ms", lease="60s") as bed:
        ts, run, topic, producer, leds, site, config = (
            bed.ts,
            bed.run,
            bed.topic,
            bed.producer,
            bed.leds,
            bed.site,
            bed.config,
        )
        with (
            TopicLog(kafka_bootstrap, schema_registry_url, config.topics.command_status) as status,
            fleet(site, ts, leds) as robots,
            running_uplink(config),
            Repeater(repeater_config(site, tmp_path / "state", dead_man="2s")) as rep,
        ):
            robots.add_robot("tb4_01")
            wait_repeater_sees(rep, "/tb4_01/cmd_lightring")
            producer.send(topic, "tb4_01", RED, command_id=f"dm-{run}")
            wait_until(lambda: leds.count("tb4_01", "red") >= 2, timeout=5, message="repeating")
            site.relay.set_mode("blackhole")
            cut_at = time.time()
            wait_until(lambda: not rep.schedule.active(), timeout=10, message="dead-man ended the command")
            ended_at = time.time()
            assert ended_at - cut_at < 2.0 + 1.0 + 1.5  # dead-man + one heartbeat timeout + slack
            publishes = rep.stats.publishes  # (none under way: see the test above)
            site.relay.set_mode("pass")
            wait_until(
                lambda: distinct(status.statuses(f"dm-{run}")) == ["delivered", "expired"],
                timeout=30,
                message="statuses reach Kafka after the heal",
            )
            expired = next(v for v in status.values() if v["status"] == "expired")
            assert expired["detail"].startswith("dead-man: no contact with the uplink")
            assert rep.stats.publishes == publishes  # stopped for good, though the lease had 50 s left
