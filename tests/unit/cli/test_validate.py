"""``fleetlink validate`` and start-up refuse bad configs by YAML path, before any socket (row 26)."""

from __future__ import annotations

import socket
from pathlib import Path
from typing import Any

import pytest

from fleetlink.cli import main
from fleetlink.cli.validate import guess_kind, validate_file
from tests.paths import DEPLOY


@pytest.fixture
def no_sockets(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*_args: Any, **_kwargs: Any) -> socket.socket:
        raise AssertionError("a socket was opened while validating a config")

    monkeypatch.setattr(socket, "socket", refuse)


def test_validating_opens_no_socket(no_sockets: None) -> None:
    kind, _ = validate_file(DEPLOY / "edge.example.yaml")
    assert kind == "edge"


BAD_UPLINK = """\
kafka:
  bootstrap_servers: 127.0.0.1:9092
  producer_overrides:
    acks: "1"
registry:
  url: http://127.0.0.1:8081
ingest:
  max_concurrent_batches: many
"""


@pytest.mark.parametrize("argv", [["validate"], ["uplink", "run", "-c"]])
def test_bad_config_exits_non_zero_naming_yaml_paths(
    argv: list[str], tmp_path: Path, no_sockets: None, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "uplink.yaml"
    path.write_text(BAD_UPLINK)
    assert main([*argv, str(path)]) == 1
    err = capsys.readouterr().err
    assert "kafka.producer_overrides (line 3)" in err
    assert "acks='1' would weaken delivery guarantees" in err
    assert "ingest.max_concurrent_batches (line 8)" in err


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("kafka: {bootstrap_servers: b}\n", "cannot tell which kind of config"),
        ("site: a\nspool: {dir: /tmp/x}\nrobot_types: {tb4: {match: 7}}\n", "robot_types.tb4.match"),
    ],
)
def test_validate_messages(
    tmp_path: Path, text: str, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "c.yaml"
    path.write_text(text)
    assert main(["validate", str(path)]) == 1
    assert message in capsys.readouterr().err


def test_missing_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", str(tmp_path / "absent.yaml")]) == 1
    assert "config file not found" in capsys.readouterr().err


def test_guess_kind() -> None:
    assert guess_kind({"site": "a", "spool": {}}) == "edge"
    assert guess_kind({"kafka": {}, "registry": {}}) == "uplink"
    assert guess_kind(["not", "a", "mapping"]) is None
