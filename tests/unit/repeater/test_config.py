"""The repeater's config: the shipped example, durations, and errors named by YAML path."""

from __future__ import annotations

import socket
from pathlib import Path
from typing import Any

import pytest
from pydantic import ValidationError

from fleetlink.cli import main
from fleetlink.cli.validate import validate_file
from fleetlink.repeater.config import RepeaterConfig
from tests.paths import DEPLOY


@pytest.fixture
def no_sockets(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*_args: Any, **_kwargs: Any) -> socket.socket:
        raise AssertionError("a socket was opened while validating a config")

    monkeypatch.setattr(socket, "socket", refuse)


def test_shipped_example_is_a_valid_repeater_config(no_sockets: None) -> None:
    kind, config = validate_file(DEPLOY / "repeater.example.yaml", host_checks=False)  # keys: test_deploy
    assert kind == "repeater"
    assert isinstance(config, RepeaterConfig)
    section = config.repeater
    assert (section.site, section.dead_man, section.heartbeat) == ("warehouse-a", 30.0, 2.0)


def with_dead_man(value: object) -> RepeaterConfig:
    section = {"site": "a", "state_dir": "/tmp/x", "command_keys": ["/k.pem"], "dead_man": value}
    return RepeaterConfig.model_validate({"repeater": section})


@pytest.mark.parametrize(
    ("text", "seconds"),
    [
        ("250ms", 0.25),
        ("1s", 1.0),
        (" 1.5 s ", 1.5),
        ("2m", 120.0),
        ("1h", 3600.0),
        (3, 3.0),
        (0.5, 0.5),
    ],
)
def test_durations(text: object, seconds: float) -> None:
    assert with_dead_man(text).repeater.dead_man == seconds


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("", "invalid duration"),
        ("1", "invalid duration"),
        ("1d", "invalid duration"),
        ("-1s", "invalid duration"),
        ("0s", "greater than 0"),
        (0, "greater than 0"),
        (True, "a duration"),
        ([1], "a duration"),
        (float("inf"), "finite"),
    ],
)
def test_bad_durations(text: object, reason: str) -> None:
    with pytest.raises(ValidationError, match=reason):
        with_dead_man(text)


def test_defaults() -> None:
    config = RepeaterConfig.model_validate(
        {"repeater": {"site": "a", "state_dir": "/tmp/x", "command_keys": ["/k.pem"]}}
    )
    assert config.repeater.dead_man is None
    assert config.repeater.id  # from the host name
    assert (config.ros.distro, config.ros.domain_id, config.zenoh.mode) == ("jazzy", 0, None)


BAD = """\
repeater:
  site: "warehouse a"
  state_dir: /tmp/x
  dead_man: soon
  id: a/b
ros:
  distro: melodic
  domain_id: 300
zenoh:
  mode: client
  colour: blue
"""


def test_bad_config_exits_non_zero_naming_yaml_paths(
    tmp_path: Path, no_sockets: None, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "repeater.yaml"
    path.write_text(BAD)
    assert main(["repeater", "run", "-c", str(path)]) == 1
    err = capsys.readouterr().err
    for where in (
        "repeater.site (line 2)",
        "repeater.dead_man (line 4)",
        "repeater.id (line 5)",
        "ros.distro (line 7)",
        "ros.domain_id (line 8)",
        "zenoh.colour (line 11)",
        "repeater.command_keys",
    ):
        assert where in err
    assert "must be one key chunk" in err
    assert "invalid duration 'soon'" in err


def test_a_repeater_without_a_key_to_check_commands_with_does_not_start(tmp_path: Path) -> None:
    with pytest.raises(ValidationError, match=r"repeater\.command_keys"):
        RepeaterConfig.model_validate(
            {"repeater": {"site": "a", "state_dir": str(tmp_path), "command_keys": []}}
        )
