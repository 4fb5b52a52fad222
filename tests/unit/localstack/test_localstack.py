"""Local stack logic that needs no server: broker properties, Java detection, messages."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest

from fleetlink.localstack import java
from fleetlink.localstack.errors import StackError
from fleetlink.localstack.kafka import KafkaSettings, server_properties
from fleetlink.localstack.registry import RegistrySettings, registry_url_lines
from tests.paths import ROOT


def _props(text: str) -> dict[str, str]:
    return dict(line.split("=", 1) for line in text.splitlines() if line)


def test_broker_properties_are_kraft_single_node_on_loopback(tmp_path: Path) -> None:
    props = _props(server_properties(KafkaSettings(port=9092, controller_port=9093, data_dir=tmp_path)))
    assert props["process.roles"] == "broker,controller"
    assert props["listeners"] == "PLAINTEXT://127.0.0.1:9092,CONTROLLER://127.0.0.1:9093"
    assert props["advertised.listeners"] == "PLAINTEXT://127.0.0.1:9092"
    assert props["offsets.topic.replication.factor"] == "1"
    assert props["log.dirs"] == str(tmp_path / "logs")


def test_advertised_port_points_clients_at_a_relay(tmp_path: Path) -> None:
    settings = KafkaSettings(port=9092, controller_port=9093, data_dir=tmp_path, advertised_port=19092)
    assert _props(server_properties(settings))["advertised.listeners"] == "PLAINTEXT://127.0.0.1:19092"
    assert settings.bootstrap == "127.0.0.1:19092"


def _fake_java(tmp_path: Path, name: str, version_line: str) -> str:
    script = tmp_path / name / "bin" / "java"
    script.parent.mkdir(parents=True)
    script.write_text(f"#!/bin/sh\necho '{version_line}' >&2\n")
    script.chmod(0o755)
    return str(script)


@pytest.mark.parametrize(
    ("line", "major"),
    [
        ('openjdk version "17.0.15" 2025-04-15', 17),
        ('openjdk version "25" 2025-09-16', 25),
        ('java version "1.8.0_392"', 8),
    ],
)
def test_java_major_version(tmp_path: Path, line: str, major: int) -> None:
    assert java.java_major_version(_fake_java(tmp_path, "jdk", line)) == major


def test_too_old_java_is_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    old = _fake_java(tmp_path, "jdk8", 'java version "1.8.0_392"')
    monkeypatch.setenv("JAVA_HOME", str(Path(old).parents[1]))
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    monkeypatch.setattr(java, "JVM_ROOT", tmp_path / "no-jvms")
    with pytest.raises(StackError, match=r"needs Java 17 or newer; found only .*jdk8/bin/java \(Java 8\)"):
        java.find_java(17, "Kafka")


def test_missing_java_says_what_to_install(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("JAVA_HOME", raising=False)
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    monkeypatch.setattr(java, "JVM_ROOT", tmp_path / "no-jvms")
    with pytest.raises(StackError, match=r"no `java` was found.*apt-get install openjdk-17"):
        java.find_java(17, "Kafka")


def test_suitable_java_is_picked_from_jvm_root(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("JAVA_HOME", raising=False)
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    _fake_java(tmp_path / "jvm", "a-jdk-17", 'openjdk version "17.0.1"')
    new = _fake_java(tmp_path / "jvm", "b-jdk-25", 'openjdk version "25"')
    monkeypatch.setattr(java, "JVM_ROOT", tmp_path / "jvm")
    assert java.find_java(21, "the registry") == new


SCRIPT = """
import signal, sys
from fleetlink.localstack.process import exit_on_sigterm
exit_on_sigterm()
try:
    print("ready", flush=True)
    signal.pause()  # until a signal: SIGTERM ends it through the handler
finally:
    open(sys.argv[1], "w").write("stopped what it started")
"""


def test_sigterm_runs_the_cleanup_of_a_script_that_asked_for_it(tmp_path: Path) -> None:
    marker = tmp_path / "cleanup"
    with subprocess.Popen(
        [sys.executable, "-c", SCRIPT, str(marker)],
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    ) as proc:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == "ready"
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 128 + signal.SIGTERM
    assert marker.read_text() == "stopped what it started"


def test_both_registry_urls_are_labelled_with_what_they_are_for(tmp_path: Path) -> None:
    settings = RegistrySettings(port=8081, data_dir=tmp_path)
    assert settings.url == "http://127.0.0.1:8081/apis/ccompat/v7"
    assert settings.native_url == "http://127.0.0.1:8081/apis/registry/v3"
    ccompat, native = registry_url_lines(settings.url)
    assert ccompat.startswith(f"{settings.url}   Confluent-compatible API: ")
    assert "fleetlink kafka" in ccompat
    assert native.startswith(f"{settings.native_url}   Apicurio native API: ")
    assert "Java" in native
    # another registry has one API only
    [only] = registry_url_lines("http://confluent:8081")
    assert only.startswith("http://confluent:8081   Confluent-compatible API: ")
