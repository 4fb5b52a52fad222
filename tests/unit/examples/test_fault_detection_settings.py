"""Settings, durations, the co-partitioning check, the command line and the command schema."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import pytest
from pydantic import ValidationError

from fleetlink.common.errors import ConfigError
from fleetlink.examples.fault_detection.app import LIGHTRING_TYPE, _RateLimitedLog, lightring_schema
from fleetlink.examples.fault_detection.cli import build_parser, settings_from_args
from fleetlink.examples.fault_detection.errors import SettingsError
from fleetlink.examples.fault_detection.rules import RuleConfig
from fleetlink.examples.fault_detection.settings import (
    DEFAULT_STATE_DIR,
    FaultDetectionSettings,
    Topics,
    check_copartitioned,
    parse_duration_ms,
)
from fleetlink.schemas.bundled import BUNDLED

IROBOT = BUNDLED / "irobot_create_msgs"
REQUIRED = ["--bootstrap", "127.0.0.1:9092", "--registry", "http://127.0.0.1:8081"]


@pytest.mark.parametrize(
    ("text", "millis"),
    [
        ("2s", 2000),
        ("500ms", 500),
        ("1.5s", 1500),
        ("1m", 60_000),
        ("2", 2000),
        (" 3 s ", 3000),
        ("0.001s", 1),
        ("1ms", 1),
        ("10000ms", 10_000),
    ],
)
def test_parse_duration(text: str, millis: int) -> None:
    assert parse_duration_ms(text) == millis


@pytest.mark.parametrize("text", ["", "abc", "-1s", "2x", "0s", "0ms", "0.5ms", "0.0005s", "1.5.0s", "s"])
def test_parse_duration_rejects(text: str) -> None:
    with pytest.raises(SettingsError, match="invalid duration"):
        parse_duration_ms(text)


def test_settings_defaults_and_rule_config() -> None:
    settings = FaultDetectionSettings(bootstrap="k:9092", registry_url="http://r")
    assert (settings.window, settings.grace, settings.min_events) == (2.0, 1.0, 2)
    assert settings.offset_reset == "latest"
    assert settings.topics == Topics(
        ir_intensity="fleet.ir_intensity",
        hazard_detection="fleet.hazard_detection",
        kidnap_status="fleet.kidnap_status",
        commands="fleet.commands.lightring",
    )
    assert settings.rule_config() == RuleConfig(
        ir_threshold=3000, failure_hazards=frozenset({2, 4}), min_events=2
    )
    custom = settings.model_copy(
        update={"ir_threshold": 10, "failure_hazards": frozenset({1}), "min_events": 5}
    )
    assert custom.rule_config() == RuleConfig(ir_threshold=10, failure_hazards=frozenset({1}), min_events=5)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("window", 0),
        ("window", "0s"),
        ("grace", -1),
        ("grace", "-1s"),
        ("min_events", 0),
        ("bootstrap", ""),
        ("offset_reset", "middle"),
        ("distro", "rolling"),
        ("poll_timeout", 0),
        ("commit_interval", "soon"),
        ("topic", "typo"),  # unknown option
    ],
)
def test_settings_reject_invalid_values(field: str, value: Any) -> None:
    with pytest.raises(ValidationError) as info:
        FaultDetectionSettings(**{"bootstrap": "k:9092", "registry_url": "http://r", field: value})
    assert field in str(info.value)


@pytest.mark.parametrize(
    ("partitions", "ok"),
    [
        ({}, True),  # none exists yet: the app creates them alike
        ({"fleet.ir_intensity": 3}, True),
        ({"fleet.ir_intensity": 3, "fleet.hazard_detection": 3, "fleet.kidnap_status": 3}, True),
        ({"fleet.ir_intensity": 3, "fleet.hazard_detection": 1}, False),
        ({"fleet.ir_intensity": 1, "fleet.hazard_detection": 1, "fleet.kidnap_status": 2}, False),
    ],
)
def test_check_copartitioned(partitions: dict[str, int], ok: bool) -> None:
    if ok:
        check_copartitioned(partitions)
        return
    with pytest.raises(SettingsError, match="same number of partitions") as info:
        check_copartitioned(partitions)
    assert all(f"{name}={count}" in str(info.value) for name, count in partitions.items())
    assert isinstance(info.value, ConfigError)


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        ([], {"window": 2.0, "grace": 1.0, "offset_reset": "latest", "msg_paths": ()}),
        (["--window", "500ms", "--grace", "0.2s"], {"window": 0.5, "grace": 0.2}),
        (["--from-beginning"], {"offset_reset": "earliest"}),
        (["--msg-path", "/a", "--msg-path", "/b"], {"msg_paths": (Path("/a"), Path("/b"))}),
        (["--failure-hazards", "4"], {"failure_hazards": frozenset({4})}),
        (["--failure-hazards", "1, 2,4"], {"failure_hazards": frozenset({1, 2, 4})}),
        (["--ir-threshold", "1500", "--min-events", "3"], {"ir_threshold": 1500, "min_events": 3}),
        (["--group", "g1", "--state-dir", "/tmp/s"], {"group": "g1", "state_dir": Path("/tmp/s")}),
        ([], {"state_dir": DEFAULT_STATE_DIR, "distro": "jazzy"}),
        (["--distro", "humble"], {"distro": "humble"}),
        (
            ["--ir-topic", "a", "--hazard-topic", "b", "--kidnap-topic", "c", "--commands-topic", "d"],
            {"topics": Topics(ir_intensity="a", hazard_detection="b", kidnap_status="c", commands="d")},
        ),
    ],
)
def test_command_line_to_settings(extra: list[str], expected: dict[str, Any]) -> None:
    settings = settings_from_args(build_parser().parse_args([*REQUIRED, *extra]))
    assert (settings.bootstrap, settings.registry_url) == ("127.0.0.1:9092", "http://127.0.0.1:8081")
    assert {name: getattr(settings, name) for name in expected} == expected


@pytest.mark.parametrize(
    "argv",
    [
        ["--registry", "http://r"],  # no --bootstrap
        [*REQUIRED, "--window", "2 weeks"],
        [*REQUIRED, "--grace", "soon"],
        [*REQUIRED, "--failure-hazards", "cliff"],
        [*REQUIRED, "--distro", "rolling"],
    ],
)
def test_command_line_rejects(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        build_parser().parse_args(argv)
    assert info.value.code == 2
    assert "error:" in capsys.readouterr().err


@pytest.mark.parametrize("msg_paths", [(IROBOT,), ()])  # given, or the copy fleetlink ships
def test_lightring_schema(msg_paths: tuple[Path, ...]) -> None:
    schema = lightring_schema(FaultDetectionSettings(bootstrap="k", registry_url="r", msg_paths=msg_paths))
    assert schema["name"] == "LightringLeds"
    assert schema["ros_type"] == LIGHTRING_TYPE
    assert [f["name"] for f in schema["fields"]] == ["header", "leds", "override_system"]
    leds = schema["fields"][1]
    assert leds["ros_type"] == "irobot_create_msgs/msg/LedColor[6]"


@pytest.mark.parametrize(
    "msg_paths",
    [
        (Path("/nonexistent/irobot_create_msgs"),),
        (IROBOT.parent,),  # the folder above the package
        (IROBOT.parent.parent,),
    ],
)
def test_lightring_schema_needs_the_package(msg_paths: tuple[Path, ...]) -> None:
    with pytest.raises(SettingsError, match="cannot derive"):
        lightring_schema(FaultDetectionSettings(bootstrap="k", registry_url="r", msg_paths=msg_paths))


@pytest.mark.parametrize(("count", "logged"), [(1, 1), (3, 1), (4, 2), (8, 3), (9, 3)])
def test_skipped_records_are_logged_first_then_every_nth(
    count: int, logged: int, caplog: pytest.LogCaptureFixture
) -> None:
    log = _RateLimitedLog(every=4)
    with caplog.at_level(logging.WARNING, logger="fleetlink.examples.fault_detection.app"):
        for i in range(count):
            log("late", f"record {i}")
        log("other-kind", "x")
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == logged + 1
    assert lines[0].startswith("record 0")
