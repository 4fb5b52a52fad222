"""The fault-detection app against a real Kafka broker and a real schema registry.

Three robots' sensor messages are produced the way fleetlink carries them (ROS message → CDR →
Avro body via the schemas codecs → Confluent framing with the registered schema's id), keyed
by robot, with the ROS stamps as record timestamps, so the windows are deterministic and nothing
waits on the wall clock: robot tb4_01 is healthy throughout, tb4_02 is picked up for longer
than the window and then put down, tb4_03 has one spurious failure reading among healthy ones.
The app runs until its consumer group has committed every input record; then the command
topic must hold exactly tb4_02's red command followed by its green one.
"""

from __future__ import annotations

import json
import logging
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from confluent_kafka import Consumer, KafkaError, KafkaException, Producer, TopicPartition
from confluent_kafka.admin import AdminClient, NewTopic
from confluent_kafka.schema_registry import Schema, SchemaRegistryClient
from confluent_kafka.schema_registry.avro import AvroDeserializer
from confluent_kafka.serialization import MessageField, SerializationContext

from fleetlink.examples.fault_detection.app import COMMAND_ID_HEADER, run
from fleetlink.examples.fault_detection.rules import HAZARD_WHEEL_DROP, LightCommand
from fleetlink.examples.fault_detection.settings import FaultDetectionSettings, Topics
from fleetlink.schemas.bundled import BUNDLED
from fleetlink.schemas.codec import get_codec
from fleetlink.schemas.typestore import load_typestore
from tests.helpers import wait_until

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

IROBOT = BUNDLED / "irobot_create_msgs"
REPO = Path(__file__).resolve().parents[2]
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


@pytest.fixture
def topics(kafka_bootstrap: str) -> Topics:
    """Fresh topics for one test, created (2 partitions each) before any app starts."""
    run_id = uuid.uuid4().hex[:8]
    names = Topics(
        ir_intensity=f"fd.{run_id}.ir_intensity",
        hazard_detection=f"fd.{run_id}.hazard_detection",
        kidnap_status=f"fd.{run_id}.kidnap_status",
        commands=f"fd.{run_id}.commands.lightring",
    )
    create_topics(kafka_bootstrap, [*sensor_topics(names).values(), names.commands])
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
    bootstrap: str, registry_url: str, topics: Topics, scenario: dict[str, list[Event]]
) -> int:
    """Produce as fleetlink does: CDR from the robot -> Avro body (schemas codec) -> Confluent framing."""
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
    for event, robot in timeline:
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


def wait_all_committed(bootstrap: str, group: str, topic_names: list[str], timeout: float) -> None:
    """Wait until ``group`` has committed the end offset of every partition of ``topic_names``."""
    consumer = Consumer({"bootstrap.servers": bootstrap, "group.id": group, "enable.auto.commit": False})

    def check() -> bool:
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
                    value=deserializer(msg.value(), SerializationContext(topic, MessageField.VALUE)),
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


@dataclass
class RunningApp:
    settings: FaultDetectionSettings
    stop: threading.Event
    done: Future[None]
    seen: list[LightCommand]


def app_settings(
    bootstrap: str, registry_url: str, topics: Topics, state_dir: Path, group: str
) -> FaultDetectionSettings:
    return FaultDetectionSettings(
        bootstrap=bootstrap,
        registry_url=registry_url,
        window=WINDOW_MS / 1000,
        group=group,
        state_dir=state_dir,
        offset_reset="earliest",
        msg_paths=(IROBOT,),
        topics=topics,
        commit_interval=0.5,
    )


@contextmanager
def app_in_thread(settings: FaultDetectionSettings) -> Iterator[RunningApp]:
    """The app in a thread (as ``fleetlink demo`` runs it); stopped and checked on exit."""
    stop = threading.Event()
    seen: list[LightCommand] = []
    with ThreadPoolExecutor(1, thread_name_prefix="fault-detection") as pool:
        app = RunningApp(settings, stop, pool.submit(run, settings, stop, seen.append), seen)
        try:
            yield app
        finally:
            stop.set()
        app.done.result(timeout=30)  # re-raises whatever ended the app


@pytest.fixture
def running_app(
    kafka_bootstrap: str, schema_registry_url: str, topics: Topics, tmp_path: Path
) -> Iterator[RunningApp]:
    group = f"fd-test-{uuid.uuid4().hex[:8]}"
    with app_in_thread(
        app_settings(kafka_bootstrap, schema_registry_url, topics, tmp_path / "state", group)
    ) as app:
        yield app


def test_one_red_then_one_green_only_for_the_robot_that_failed_longer_than_the_window(
    kafka_bootstrap: str,
    schema_registry_url: str,
    topics: Topics,
    running_app: RunningApp,
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.WARNING, logger="fleetlink.examples.fault_detection")
    settings, seen = running_app.settings, running_app.seen
    produced = produce_scenario(kafka_bootstrap, schema_registry_url, topics, SCENARIO)
    assert produced == 3 * 3 * (DURATION_MS // PERIOD_MS)

    wait_all_committed(kafka_bootstrap, settings.group, list(sensor_topics(topics).values()), timeout=45)
    commands = read_commands(kafka_bootstrap, schema_registry_url, topics.commands)

    # the reference model agrees with the scenario's intent before it judges the app
    assert expected_changes(SCENARIO["tb4_01"], WINDOW_MS) == []
    assert expected_changes(SCENARIO["tb4_03"], WINDOW_MS) == []
    changes = expected_changes(SCENARIO["tb4_02"], WINDOW_MS)
    assert [state for state, _ in changes] == ["failed", "running"]
    (_, red_at), (_, green_at) = changes
    assert T0 + 2000 + WINDOW_MS <= red_at <= T0 + 2000 + WINDOW_MS + PERIOD_MS
    assert T0 + 5500 + WINDOW_MS <= green_at <= T0 + 5500 + WINDOW_MS + PERIOD_MS

    assert [c.key for c in commands] == ["tb4_02", "tb4_02"]
    red, green = commands
    assert colours(red) == {RED}
    assert colours(green) == {GREEN}
    for command, at, state in ((red, red_at, "failed"), (green, green_at, "running")):
        assert len(command.value["leds"]) == 6
        assert command.value["override_system"] is True
        assert command.timestamp == at
        assert command.value["header"]["stamp"] == {"sec": at // 1000, "nanosec": (at % 1000) * 1_000_000}
        assert command.command_id == f"tb4_02-{state}-{at}"
    assert [(c.robot, c.state.value, c.stamp_ms) for c in seen] == [
        ("tb4_02", "failed", red_at),
        ("tb4_02", "running", green_at),
    ]

    latest = SchemaRegistryClient({"url": schema_registry_url}).get_latest_version(f"{topics.commands}-value")
    assert '"LightringLeds"' in latest.schema.schema_str

    # a robot that joins while the app runs is judged like the others, nothing restarted
    late_joiner = shifted(robot_events(lambda _s, t: t >= 1000), DURATION_MS)
    produce_scenario(kafka_bootstrap, schema_registry_url, topics, {"tb4_04": late_joiner})
    [(state, joined_red_at)] = expected_changes(late_joiner, WINDOW_MS)
    wait_all_committed(kafka_bootstrap, settings.group, list(sensor_topics(topics).values()), timeout=30)
    new_commands = read_commands(kafka_bootstrap, schema_registry_url, topics.commands)[2:]
    assert [(c.key, colours(c), c.timestamp) for c in new_commands] == [("tb4_04", {RED}, joined_red_at)]

    # every record counted: none skipped as late, undecodable or malformed
    skipped = [
        r.getMessage() for r in caplog.records if r.name.startswith("fleetlink.examples.fault_detection")
    ]
    assert skipped == []

    # a stop request ends the app promptly (finish the record in hand, commit, close)
    started = time.monotonic()
    running_app.stop.set()
    running_app.done.result(timeout=20)
    assert time.monotonic() - started < 10


def test_cli_subprocess_detects_a_fault_and_stops_on_sigterm(
    kafka_bootstrap: str, schema_registry_url: str, topics: Topics, tmp_path: Path
) -> None:
    # an undecodable record, then one robot picked up from 1 s to the end: the bad record is
    # logged and skipped, the robot gets one red command and nothing else
    producer = Producer({"bootstrap.servers": kafka_bootstrap})
    producer.produce(topics.ir_intensity, key=b"tb4_07", value=b"not an avro record", timestamp=T0 - 1000)
    assert producer.flush(10) == 0
    events = robot_events(lambda _s, t: t >= 1000)
    produce_scenario(kafka_bootstrap, schema_registry_url, topics, {"tb4_07": events})
    [(state, red_at)] = expected_changes(events, 1500)
    assert state == "failed"
    argv = [
        sys.executable, "-m", "fleetlink.examples.fault_detection",
        "--bootstrap", kafka_bootstrap, "--registry", schema_registry_url,
        "--window", "1500ms", "--group", f"fd-cli-{uuid.uuid4().hex[:8]}",
        "--state-dir", str(tmp_path / "state"), "--from-beginning",
        "--ir-topic", topics.ir_intensity, "--hazard-topic", topics.hazard_detection,
        "--kidnap-topic", topics.kidnap_status, "--commands-topic", topics.commands, "-v",
    ]  # fmt: skip
    proc = subprocess.Popen(argv, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")), daemon=True)  # type: ignore[union-attr]
    reader.start()
    try:
        wait_until(
            lambda: any("tb4_07-failed-" in line for line in lines) or proc.poll() is not None,
            timeout=45,
            interval=0.1,
            message="the CLI logged the state change",
        )
        assert proc.poll() is None, "".join(lines)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=20) == 0, "".join(lines)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    reader.join(5)
    assert any("skipping undecodable record" in line and topics.ir_intensity in line for line in lines)
    commands = read_commands(kafka_bootstrap, schema_registry_url, topics.commands)
    assert [(c.key, colours(c)) for c in commands] == [("tb4_07", {RED})]
    assert commands[0].timestamp == red_at
    assert commands[0].command_id == f"tb4_07-failed-{red_at}"


def test_state_survives_a_restart_on_a_fresh_disk(
    kafka_bootstrap: str, schema_registry_url: str, topics: Topics, tmp_path: Path
) -> None:
    """Failed before the restart stays failed after it (no second red); recovery is one green.

    The second run gets an empty state folder, so the robot's state and its open windows come
    back from the changelog topic in Kafka, not from the local disk.
    """
    group = f"fd-restart-{uuid.uuid4().hex[:8]}"
    names = list(sensor_topics(topics).values())
    events = robot_events(lambda _s, t: 1000 <= t < 6000)
    first, second = [e for e in events if e.ts < T0 + 5000], [e for e in events if e.ts >= T0 + 5000]
    (_, red_at), (_, green_at) = expected_changes(events, WINDOW_MS)
    assert red_at < T0 + 5000 < green_at

    with app_in_thread(
        app_settings(kafka_bootstrap, schema_registry_url, topics, tmp_path / "one", group)
    ) as app:
        produce_scenario(kafka_bootstrap, schema_registry_url, topics, {"tb4_05": first})
        wait_all_committed(kafka_bootstrap, group, names, timeout=45)
    assert [(c.state.value, c.stamp_ms) for c in app.seen] == [("failed", red_at)]

    with app_in_thread(
        app_settings(kafka_bootstrap, schema_registry_url, topics, tmp_path / "two", group)
    ) as app:
        produce_scenario(kafka_bootstrap, schema_registry_url, topics, {"tb4_05": second})
        wait_all_committed(kafka_bootstrap, group, names, timeout=45)
    assert [(c.state.value, c.stamp_ms) for c in app.seen] == [("running", green_at)]

    commands = read_commands(kafka_bootstrap, schema_registry_url, topics.commands)
    assert [(c.key, colours(c), c.timestamp) for c in commands] == [
        ("tb4_05", {RED}, red_at),
        ("tb4_05", {GREEN}, green_at),
    ]


def test_latency_tool_measures_window_and_app_parts(kafka_bootstrap: str, schema_registry_url: str) -> None:
    """The measurement tool runs (examples are tested artefacts) and its figures add up."""
    argv = [
        sys.executable, "-m", "fleetlink.examples.fault_detection.latency",
        "--bootstrap", kafka_bootstrap, "--registry", schema_registry_url, "--msg-path", str(IROBOT),
        "--window", "500ms", "--rate", "20", "--runs", "1",
    ]  # fmt: skip
    done = subprocess.run(argv, cwd=REPO, capture_output=True, text=True, timeout=90, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    rows = [line.split() for line in done.stdout.splitlines() if line.startswith(("failed ", "running "))]
    assert [row[0] for row in rows] == ["failed", "running"]
    for row in rows:
        window, app = int(row[5]), int(row[8])
        assert 500 - 200 < window <= 500 + 100
        assert 0 <= app < 2000
    assert (
        sum(
            line.split()[0] in {"total", "window", "app"} and "p50" in line
            for line in done.stdout.splitlines()
        )
        == 3
    )
