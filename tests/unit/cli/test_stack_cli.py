"""``fleetlink stack status`` reads the stack's state file: both registry URLs, labelled."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fleetlink.cli import main
from fleetlink.localstack.stack import StackInfo

DEAD_PID = 2**22 + 1  # above the kernel's pid_max default: never a live process


def _stack(tmp_path: Path) -> Path:
    StackInfo(
        bootstrap="127.0.0.1:9092",
        registry_url="http://127.0.0.1:8081/apis/ccompat/v7",
        kafka_pid=DEAD_PID,
        registry_pid=DEAD_PID,
        kafka_seconds=4.0,
        registry_seconds=7.0,
    ).save(tmp_path)
    return tmp_path


def test_status_prints_both_registry_urls(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["stack", "status", "--dir", str(_stack(tmp_path))]) == 3  # not running
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "not running (stale state): Kafka 127.0.0.1:9092"
    assert lines[1].startswith("Registry  http://127.0.0.1:8081/apis/ccompat/v7   Confluent-compatible API")
    assert lines[2].startswith("Registry  http://127.0.0.1:8081/apis/registry/v3   Apicurio native API")


def test_status_json_carries_the_native_url(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["stack", "status", "--dir", str(_stack(tmp_path)), "--json"]) == 3
    status = json.loads(capsys.readouterr().out)
    assert status["running"] is False
    assert status["registry_url"] == "http://127.0.0.1:8081/apis/ccompat/v7"
    assert status["registry_native_url"] == "http://127.0.0.1:8081/apis/registry/v3"
