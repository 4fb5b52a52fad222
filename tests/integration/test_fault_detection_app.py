"""The fault-detection app against a real Kafka broker and a real schema registry.

Three robots' sensor messages are produced the way fleetlink carries them (ROS message → CDR →
Avro body via the schemas codecs → Confluent framing with the registered schema's id), keyed
by robot, with the ROS stamps as record timestamps, so the windows are deterministic and nothing
waits on the wall clock: robot tb4_01 is healthy throughout, tb4_02 is picked up for longer
than the window and then put down, tb4_03 has one spurious failure reading among healthy ones.
The app runs until its consumer group has committed every input record; then the command
topic must hold exactly tb4_02's red command followed by its green one. The scenario and the
reference model are in fault_scenario.py (the Kafka Streams app is judged on them too).
"""

from __future__ import annotations

import logging
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest
from confluent_kafka import Producer
from confluent_kafka.schema_registry import SchemaRegistryClient

from fleetlink.examples.fault_detection.app import run
from fleetlink.examples.fault_detection.rules import LightCommand
from fleetlink.examples.fault_detection.settings import FaultDetectionSettings, Topics
from tests.helpers import wait_until
from tests.integration.fault_scenario import (
    DURATION_MS,
    GREEN,
    IROBOT,
    PERIOD_MS,
    RED,
    SCENARIO,
    T0,
    WINDOW_MS,
    colours,
    expected_changes,
    fresh_topics,
    produce_scenario,
    read_commands,
    robot_events,
    sensor_topics,
    shifted,
    wait_all_committed,
)

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def topics(kafka_bootstrap: str) -> Topics:
    return fresh_topics(kafka_bootstrap)


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
    produced = produce_scenario(kafka_bootstrap, schema_registry_url, topics, SCENARIO, live=True)
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
    produce_scenario(kafka_bootstrap, schema_registry_url, topics, {"tb4_04": late_joiner}, live=True)
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
        produce_scenario(kafka_bootstrap, schema_registry_url, topics, {"tb4_05": first}, live=True)
        wait_all_committed(kafka_bootstrap, group, names, timeout=45)
    assert [(c.state.value, c.stamp_ms) for c in app.seen] == [("failed", red_at)]

    with app_in_thread(
        app_settings(kafka_bootstrap, schema_registry_url, topics, tmp_path / "two", group)
    ) as app:
        produce_scenario(kafka_bootstrap, schema_registry_url, topics, {"tb4_05": second}, live=True)
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
        window, app, gap, due = int(row[5]), int(row[8]), int(row[11]), int(row[14])
        # never before a whole window after the last record before the change, and no later
        # than the first record that completes one (however late the robot published it)
        assert window + gap > 500
        assert window <= due
        assert gap > 0
        assert 0 <= app < 2000
    assert (
        sum(
            line.split()[0] in {"total", "window", "app"} and "p50" in line
            for line in done.stdout.splitlines()
        )
        == 3
    )
