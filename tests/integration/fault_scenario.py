"""The fault-detection scenario both apps are judged on, and the Kafka plumbing around it.

Three robots' sensor messages are produced the way fleetlink carries them (ROS message → CDR →
Avro body via the schemas codecs → Confluent framing with the registered schema's id), keyed
by robot, with the ROS stamps as record timestamps, so the windows are deterministic and nothing
waits on the wall clock. ``expected_changes`` is the reference model of the rule; the Quix
Streams app (test_fault_detection_app.py) and the Kafka Streams app (test_kafka_streams_app.py)
must both agree with it.
"""

from __future__ import annotations

import json
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Any

from confluent_kafka import Consumer, KafkaError, KafkaException, Producer, TopicPartition
from confluent_kafka.admin import AdminClient, NewTopic
from confluent_kafka.schema_registry import Schema, SchemaRegistryClient
from confluent_kafka.schema_registry.avro import AvroDeserializer
from confluent_kafka.serialization import MessageField, SerializationContext

from fleetlink.examples.fault_detection.app import COMMAND_ID_HEADER
from fleetlink.examples.fault_detection.rules import HAZARD_WHEEL_DROP
from fleetlink.examples.fault_detection.settings import Topics
from fleetlink.schemas.bundled import BUNDLED
from fleetlink.schemas.codec import get_codec
from fleetlink.schemas.registry import on_a_live_connection
from fleetlink.schemas.typestore import load_typestore
from tests.helpers import wait_until

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

IROBOT = BUNDLED / "irobot_create_msgs"
PKG = "irobot_create_msgs/msg/"
WINDOW_MS = 2000
# Event time of the first record (ms): ten minutes ago, in whole seconds. Recent on purpose:
# the broker's time-based retention (7 days) deletes records stamped long ago within minutes.
T0 = (time.time_ns() // 1_000_000_000 - 600) * 1000
PERIOD_MS = 100
DURATION_MS = 9000
HEALTHY_IR = [12, 40, 7, 300, 25, 0, 18]
PICKED_UP_IR = [3900, 3500, 4000, 3300, 3600, 3100, 3700]
BUMP = 1
RED, GREEN = (255, 0, 0), (0, 255, 0)


@dataclass(frozen=True)
class Event:
    sensor: str  # "ir" | "hazard" | "kidnap"
    ts: int
    failure: bool


def robot_events(fault: Callable[[str, int], bool]) -> list[Event]:
    """Each sensor every PERIOD_MS (staggered); ``fault(sensor, offset_ms)`` says which fail."""
    events = []
    for offset in range(0, DURATION_MS, PERIOD_MS):
        for sensor, stagger in (("ir", 0), ("kidnap", 30), ("hazard", 60)):
            t = offset + stagger
            events.append(Event(sensor, T0 + t, fault(sensor, t)))
    return events


def shifted(events: list[Event], by_ms: int) -> list[Event]:
    return [Event(e.sensor, e.ts + by_ms, e.failure) for e in events]


SCENARIO: dict[str, list[Event]] = {
    "tb4_01": robot_events(lambda _s, _t: False),
    # picked up from 2.0 s to 5.5 s (longer than the 2 s window), then put down
    "tb4_02": robot_events(lambda _s, t: 2000 <= t < 5500),
    # one kidnapped reading at 4.03 s among healthy ones
    "tb4_03": robot_events(lambda s, t: s == "kidnap" and t == 4030),
}


def expected_changes(events: list[Event], window_ms: int, min_events: int = 2) -> list[tuple[str, int]]:
    """Reference model: judge the window [t - window, t] at every event, one change per flip."""
    state, changes = "running", []
    for e in sorted(events, key=lambda e: e.ts):
        inside = [x for x in events if e.ts - window_ms <= x.ts <= e.ts]
        failures = sum(x.failure for x in inside)
        verdict = None
        if len(inside) >= min_events:
            verdict = "failed" if failures == len(inside) else "running" if failures == 0 else None
        if verdict is not None and verdict != state:
            state = verdict
            changes.append((state, e.ts))
    return changes


def ros_message(ts: Typestore, event: Event) -> Any:
    """The ROS message a TurtleBot 4 would publish for ``event`` (a rosbags message object)."""
    types = ts.types
    stamp = types["builtin_interfaces/msg/Time"](sec=event.ts // 1000, nanosec=(event.ts % 1000) * 1_000_000)
    header = types["std_msgs/msg/Header"](stamp=stamp, frame_id="base_link")
    if event.sensor == "ir":
        values = PICKED_UP_IR if event.failure else HEALTHY_IR
        reading = types[PKG + "IrIntensity"]
        return types[PKG + "IrIntensityVector"](
            header=header, readings=[reading(header=header, value=v) for v in values]
        )
    if event.sensor == "kidnap":
        return types[PKG + "KidnapStatus"](header=header, is_kidnapped=event.failure)
    detection = types[PKG + "HazardDetection"]
    kinds = [BUMP, HAZARD_WHEEL_DROP] if event.failure else [BUMP]
    return types[PKG + "HazardDetectionVector"](
        header=header, detections=[detection(header=header, type=k) for k in kinds]
    )


SENSOR_TYPES = {"ir": "IrIntensityVector", "hazard": "HazardDetectionVector", "kidnap": "KidnapStatus"}


def fresh_topics(bootstrap: str) -> Topics:
    """Fresh topics for one test, created (2 partitions each) before any app starts."""
    run_id = uuid.uuid4().hex[:8]
    names = Topics(
        ir_intensity=f"fd.{run_id}.ir_intensity",
        hazard_detection=f"fd.{run_id}.hazard_detection",
        kidnap_status=f"fd.{run_id}.kidnap_status",
        commands=f"fd.{run_id}.commands.lightring",
    )
    create_topics(bootstrap, [*sensor_topics(names).values(), names.commands])
    return names


def sensor_topics(topics: Topics) -> dict[str, str]:
    return {"ir": topics.ir_intensity, "hazard": topics.hazard_detection, "kidnap": topics.kidnap_status}


def create_topics(bootstrap: str, names: list[str], partitions: int = 2) -> None:
    admin = AdminClient({"bootstrap.servers": bootstrap})
    futures = admin.create_topics(
        [NewTopic(n, num_partitions=partitions, replication_factor=1) for n in names]
    )
    for future in futures.values():
        future.result(timeout=30)


def produce_scenario(
    bootstrap: str, registry_url: str, topics: Topics, scenario: dict[str, list[Event]], *, live: bool = False
) -> int:
    """Produce as fleetlink does: CDR from the robot -> Avro body (schemas codec) -> Confluent framing.

    ``live``: each event when its time comes, as robots publish to an app that is running. Replayed
    at once instead, a new robot's three topic partitions fill one after the other, and the app
    reads one ahead of the others by more than its grace (its idle partitions seem to have
    nothing): records counted as late, a decision moved. Without ``live``, produce before the
    app starts."""
    ts = load_typestore("jazzy", msg_paths=[IROBOT])
    registry = SchemaRegistryClient({"url": registry_url})
    names = sensor_topics(topics)
    codecs, prefixes = {}, {}
    for sensor, typename in SENSOR_TYPES.items():
        codecs[sensor] = get_codec(ts, PKG + typename, "jazzy")
        schema_id = registry.register_schema(
            f"{names[sensor]}-value", Schema(json.dumps(codecs[sensor].schema), "AVRO")
        )
        prefixes[sensor] = b"\x00" + schema_id.to_bytes(4, "big")
    producer = Producer({"bootstrap.servers": bootstrap, "acks": "all", "enable.idempotence": True})
    errors: list[object] = []
    # all robots at once, in event-time order, as a live fleet produces them
    timeline = sorted(
        ((e, robot) for robot, events in scenario.items() for e in events), key=lambda p: p[0].ts
    )
    started, first_ts = time.monotonic(), timeline[0][0].ts if timeline else 0
    for event, robot in timeline:
        if live and (ahead := started + (event.ts - first_ts) / 1000 - time.monotonic()) > 0:
            time.sleep(ahead)  # ok-sleep: the robot's pace
        typename = PKG + SENSOR_TYPES[event.sensor]
        cdr = bytes(ts.serialize_cdr(ros_message(ts, event), typename))
        producer.produce(
            names[event.sensor],
            key=robot.encode(),
            value=prefixes[event.sensor] + codecs[event.sensor].cdr_to_avro(cdr),
            timestamp=event.ts,
            on_delivery=lambda err, _msg: errors.append(err) if err else None,
        )
        producer.poll(0)
    assert producer.flush(30) == 0
    assert errors == []
    return len(timeline)


COORDINATOR_PENDING = {
    KafkaError.NOT_COORDINATOR,
    KafkaError.COORDINATOR_NOT_AVAILABLE,
    KafkaError.COORDINATOR_LOAD_IN_PROGRESS,
    KafkaError._TIMED_OUT,
}


def wait_all_committed(
    bootstrap: str,
    group: str,
    topic_names: list[str],
    timeout: float,
    stopped: Callable[[], bool] = lambda: False,
) -> None:
    """Wait until ``group`` has committed the end offset of every partition of ``topic_names``.

    ``stopped``: the app has ended (a process that exited): fail at once instead of waiting on.
    """
    consumer = Consumer({"bootstrap.servers": bootstrap, "group.id": group, "enable.auto.commit": False})

    def check() -> bool:
        if stopped():
            raise AssertionError(f"the app of group {group} stopped before committing {topic_names}")
        metadata = consumer.list_topics(timeout=5)
        tps = [TopicPartition(t, p) for t in topic_names for p in metadata.topics[t].partitions]
        try:
            offsets = consumer.committed(tps, timeout=5)
        except KafkaException as exc:  # e.g. a fresh broker still electing the group coordinator
            if exc.args[0].retriable() or exc.args[0].code() in COORDINATOR_PENDING:
                return False
            raise
        committed = {(tp.topic, tp.partition): tp.offset for tp in offsets}
        for tp in tps:
            _low, high = consumer.get_watermark_offsets(tp, timeout=5)
            if high > 0 and committed[(tp.topic, tp.partition)] < high:
                return False
        return True

    try:
        wait_until(check, timeout=timeout, interval=0.2, message=f"group {group} committed {topic_names}")
    finally:
        consumer.close()


@dataclass(frozen=True)
class Command:
    key: str
    value: dict[str, Any]
    command_id: str
    timestamp: int


def read_commands(bootstrap: str, registry_url: str, topic: str) -> list[Command]:
    """Every record of ``topic`` (all partitions, start to end), decoded with the stock deserializer."""
    consumer = Consumer(
        {"bootstrap.servers": bootstrap, "group.id": f"reader-{uuid.uuid4()}", "enable.auto.commit": False}
    )
    deserializer = AvroDeserializer(SchemaRegistryClient({"url": registry_url}))
    try:
        partitions = consumer.list_topics(topic, timeout=10).topics[topic].partitions
        ends = {p: consumer.get_watermark_offsets(TopicPartition(topic, p), timeout=5)[1] for p in partitions}
        consumer.assign([TopicPartition(topic, p, 0) for p in partitions])
        got: list[Command] = []
        seen = dict.fromkeys(partitions, 0)
        context = SerializationContext(topic, MessageField.VALUE)
        deadline = time.monotonic() + 20
        while any(seen[p] < ends[p] for p in partitions) and time.monotonic() < deadline:
            msg = consumer.poll(0.2)
            if msg is None or msg.error():
                continue
            seen[msg.partition()] = msg.offset() + 1
            headers = dict(msg.headers() or [])
            got.append(
                Command(
                    key=msg.key().decode(),
                    value=on_a_live_connection(partial(deserializer, msg.value(), context)),
                    command_id=headers[COMMAND_ID_HEADER].decode(),
                    timestamp=msg.timestamp()[1],
                )
            )
        assert all(seen[p] >= ends[p] for p in partitions), f"read {seen} of {ends}"
    finally:
        consumer.close()
    return sorted(got, key=lambda c: c.timestamp)


def colours(command: Command) -> set[tuple[int, int, int]]:
    return {(led["red"], led["green"], led["blue"]) for led in command.value["leds"]}
