"""The Kafka Streams (Java) fault-detection app against a real Kafka broker and a real registry.

The jar is built with Maven (``mvn -q -B package``, session fixture) and run as its own process,
on the scenario the Quix Streams app is judged on (fault_scenario.py): three robots in event time
plus one undecodable record. The command topic must hold exactly what the reference model of the
rule says, with the stamps, LEDs, keys and command ids the Python app writes; the command schema
it registers must be one the uplink can read (whole, no references); SIGTERM stops it with exit 0.
"""

from __future__ import annotations

import json
import signal
import subprocess
import threading
import uuid
from pathlib import Path

import fastavro
import httpx
import pytest
from confluent_kafka import Producer

from fleetlink.examples import kafka_streams
from fleetlink.examples.fault_detection.settings import Topics
from fleetlink.localstack.java import find_java
from fleetlink.schemas.registry_urls import apicurio_native_url
from tests.helpers import wait_until
from tests.integration.fault_scenario import (
    GREEN,
    RED,
    SCENARIO,
    T0,
    WINDOW_MS,
    colours,
    expected_changes,
    fresh_topics,
    produce_scenario,
    read_commands,
    sensor_topics,
    wait_all_committed,
)


@pytest.fixture
def topics(kafka_bootstrap: str) -> Topics:
    return fresh_topics(kafka_bootstrap)


def test_the_java_app_decides_as_the_reference_model_and_stops_on_sigterm(
    kafka_streams_jar: Path, kafka_bootstrap: str, schema_registry_url: str, topics: Topics, tmp_path: Path
) -> None:
    native = apicurio_native_url(schema_registry_url)
    assert native is not None
    producer = Producer({"bootstrap.servers": kafka_bootstrap})
    producer.produce(topics.ir_intensity, key=b"tb4_01", value=b"not an avro record", timestamp=T0 - 1000)
    assert producer.flush(10) == 0
    produced = produce_scenario(kafka_bootstrap, schema_registry_url, topics, SCENARIO)

    group = f"fd-java-{uuid.uuid4().hex[:8]}"
    argv = kafka_streams.command(
        find_java(17),
        bootstrap=kafka_bootstrap,
        registry_native_url=native,
        window_ms=WINDOW_MS,
        group=group,
        state_dir=tmp_path / "state",
        from_beginning=True,
        extra=(
            "--ir-topic", topics.ir_intensity, "--hazard-topic", topics.hazard_detection,
            "--kidnap-topic", topics.kidnap_status, "--commands-topic", topics.commands,
        ),
    )  # fmt: skip
    assert argv[argv.index("-jar") + 1] == str(kafka_streams_jar)
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")), daemon=True)  # type: ignore[union-attr]
    reader.start()
    try:
        wait_until(
            lambda: proc.poll() is not None or any(kafka_streams.READY_LINE in line for line in lines),
            timeout=60,
            interval=0.1,
            message="the Java app running",
        )
        assert proc.poll() is None, "".join(lines)
        wait_all_committed(
            kafka_bootstrap,
            group,
            list(sensor_topics(topics).values()),
            timeout=60,
            stopped=lambda: proc.poll() is not None,
        )
        assert proc.poll() is None, "".join(lines)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 0, "".join(lines)
    except AssertionError as exc:
        raise AssertionError(f"{exc}\n--- the Java app's output:\n{''.join(lines)}") from exc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    reader.join(5)
    told = "".join(lines)

    assert produced == sum(len(events) for events in SCENARIO.values())
    changes = expected_changes(SCENARIO["tb4_02"], WINDOW_MS)
    assert [state for state, _ in changes] == ["failed", "running"]
    assert expected_changes(SCENARIO["tb4_01"], WINDOW_MS) == []
    assert expected_changes(SCENARIO["tb4_03"], WINDOW_MS) == []
    (_, red_at), (_, green_at) = changes

    commands = read_commands(kafka_bootstrap, schema_registry_url, topics.commands)
    assert [c.key for c in commands] == ["tb4_02", "tb4_02"], told
    red, green = commands
    assert colours(red) == {RED}
    assert colours(green) == {GREEN}
    for command, at, state in ((red, red_at, "failed"), (green, green_at, "running")):
        assert len(command.value["leds"]) == 6
        assert command.value["override_system"] is True
        assert command.timestamp == at
        assert command.value["header"] == {
            "stamp": {"sec": at // 1000, "nanosec": (at % 1000) * 1_000_000},
            "frame_id": "",
        }
        assert command.command_id == f"tb4_02-{state}-{at}"

    # what the app told: both decisions, and the undecodable record skipped, not fatal
    changes_told = [kafka_streams.parse_state_change(line) for line in lines]
    assert [(c.robot, c.before, c.after, c.window_end_ms) for c in changes_told if c] == [
        ("tb4_02", "running", "failed", red_at),
        ("tb4_02", "failed", "running", green_at),
    ]
    assert "skipping undecodable record topic=" + topics.ir_intensity in told
    assert "not the Confluent wire format: magic byte 0x6e is not 0x00" in told
    assert "Skipping record due to deserialization error" not in told  # Kafka Streams' own line, per record

    # the command schema is registered whole, as fleetlink's are: a Confluent reader needs no references
    subject = f"{topics.commands}-value"
    latest = httpx.get(f"{schema_registry_url}/subjects/{subject}/versions/latest", timeout=10).json()
    assert not latest.get("references"), latest
    parsed = fastavro.parse_schema(json.loads(latest["schema"]))
    assert isinstance(parsed, dict)
    assert parsed["name"] == "ros.irobot_create_msgs.msg.LightringLeds"


def test_the_confluent_compatible_url_is_refused_with_the_native_one(
    kafka_streams_jar: Path, kafka_bootstrap: str, schema_registry_url: str
) -> None:
    argv = [find_java(17), "-jar", str(kafka_streams_jar), "--bootstrap", kafka_bootstrap]
    done = subprocess.run(
        [*argv, "--registry", schema_registry_url], capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 2
    assert f"--registry {apicurio_native_url(schema_registry_url)}" in done.stderr
