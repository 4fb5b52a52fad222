"""Command mappings: templates, which robot a record addresses, and config errors by YAML path."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from pydantic import ValidationError

from fleetlink.common.configfile import load_config
from fleetlink.common.errors import ConfigError
from fleetlink.uplink.commands.errors import RoutingError
from fleetlink.uplink.commands.mapping import CommandMapping, Ref, Target, parse_template, targets
from fleetlink.uplink.config import UplinkConfig

TYPE = "irobot_create_msgs/msg/LightringLeds"


def mapping(**fields: Any) -> CommandMapping:
    base: dict[str, Any] = {
        "name": "lightring",
        "from": "fleet.commands",
        "to": "/{key}/cmd_lightring",
        "type": TYPE,
    }
    return CommandMapping.model_validate({**base, **fields})


@pytest.mark.parametrize(
    ("text", "parts"),
    [
        ("/{key}/cmd", ("/", Ref("key"), "/cmd")),
        ("/{ msg.robot_id }/task", ("/", Ref("msg", ("robot_id",)), "/task")),
        ("/fleet/{robot}/{msg.a.b_2}", ("/fleet/", Ref("robot"), "/", Ref("msg", ("a", "b_2")))),
        ("/static", ("/static",)),
    ],
)
def test_templates_parse(text: str, parts: tuple[object, ...]) -> None:
    assert parse_template(text).parts == parts


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("/{robots}/cmd", "unknown placeholder {robots}"),
        ("/{msg}/cmd", "unknown placeholder {msg}"),
        ("/{msg.1x}/cmd", "unknown placeholder"),
        ("/{key/cmd", "unbalanced brace"),
        ("/key}/cmd", "unbalanced brace"),
    ],
)
def test_bad_templates(text: str, reason: str) -> None:
    with pytest.raises(ValueError, match=reason):
        parse_template(text)


@pytest.mark.parametrize(
    ("fields", "ref"),
    [
        ({}, Ref("key")),
        ({"to": "/{msg.robot_id}/task"}, Ref("msg", ("robot_id",))),
        ({"to": "/fleet/{key}/task"}, Ref("key")),
        ({"to": "/{robot}/task"}, Ref("key")),
        ({"to": "/{key}/task", "robot": "{msg.target.name}"}, Ref("msg", ("target", "name"))),
        ({"to": "/{robot}/cmd_lightring", "broadcast": True}, None),
    ],
)
def test_which_robot_a_mapping_addresses(fields: dict[str, Any], ref: Ref | None) -> None:
    assert mapping(**fields).robot_ref == ref


RECORD = {"robot_id": "tb4_07", "target": {"name": "tb4_08", "slot": 3}, "flag": True, "ratio": 0.5}


@pytest.mark.parametrize(
    ("fields", "key", "known", "expected"),
    [
        ({}, "tb4_01", (), [Target("tb4_01", "/tb4_01/cmd_lightring")]),
        ({"to": "/{msg.robot_id}/task"}, None, (), [Target("tb4_07", "/tb4_07/task")]),
        (
            {"to": "/{robot}/slot_{msg.target.slot}", "robot": "{msg.target.name}"},
            "k",
            (),
            [Target("tb4_08", "/tb4_08/slot_3")],
        ),
        (
            {"to": "/{robot}/cmd", "broadcast": True},
            None,
            ("tb4_02", "tb4_01", "tb4_02"),
            [Target("tb4_01", "/tb4_01/cmd"), Target("tb4_02", "/tb4_02/cmd")],
        ),
        ({"to": "/{robot}/cmd", "broadcast": True}, None, (), []),
        ({}, "fleet/tb4_01", (), [Target("fleet/tb4_01", "/fleet/tb4_01/cmd_lightring")]),
    ],
)
def test_targets(
    fields: dict[str, Any], key: str | None, known: tuple[str, ...], expected: list[Target]
) -> None:
    assert targets(mapping(**fields), key=key, record=RECORD, known_robots=known) == expected


@pytest.mark.parametrize(
    ("fields", "key", "reason"),
    [
        ({}, None, "the record has no key"),
        ({}, "", "the record has no key"),
        ({"to": "/{msg.missing}/task"}, "k", "no field missing"),
        ({"to": "/{msg.target.none}/task"}, "k", "no field target.none"),
        ({"to": "/{msg.flag}/task"}, "k", "is a bool"),
        ({"to": "/{msg.ratio}/task"}, "k", "is a float"),
        ({"to": "/{msg.target}/task"}, "k", "is a dict"),
        ({}, "tb4 01", "cannot be used in a key expression"),
        ({}, "tb4-01", "no valid ROS topic"),
        ({}, "*", "cannot be used in a key expression"),
    ],
)
def test_records_that_address_no_usable_robot(fields: dict[str, Any], key: str | None, reason: str) -> None:
    with pytest.raises(RoutingError, match=reason):
        targets(mapping(**fields), key=key, record=RECORD)


@pytest.mark.parametrize(
    ("fields", "reason"),
    [
        ({"name": "light ring"}, "one key chunk"),
        ({"from": "fleet commands"}, "Kafka topic names use only"),
        ({"type": "LightringLeds"}, "must look like 'package/msg/Type'"),
        ({"to": "{key}/cmd"}, "absolute ROS topic"),
        ({"to": "/{key}//cmd"}, "makes no valid ROS topic"),
        ({"to": "/{nope}/cmd"}, "unknown placeholder"),
        ({"robot": "{robot}"}, "exactly one of"),
        ({"robot": "tb4_{key}"}, "exactly one of"),
        ({"to": "/{key}/cmd", "broadcast": True}, "needs {robot}"),
        ({"to": "/{robot}/cmd", "broadcast": True, "robot": "{key}"}, "drop 'robot'"),
        ({"repeat": {"period": "5s", "lease": "1s"}}, "published once"),
        ({"repeat": {"period": "0s"}}, "greater than 0"),
        ({"qos": {"depth": 0}}, "greater than or equal to 1"),
        ({"qos": {"durability": "persistent"}}, "volatile"),
        ({"colour": "red"}, "Extra inputs"),
    ],
)
def test_invalid_mappings(fields: dict[str, Any], reason: str) -> None:
    with pytest.raises(ValidationError, match=reason):
        mapping(**fields)


def test_derived_values() -> None:
    m = mapping(
        repeat={"period": "250ms", "lease": "1m"},
        qos={"reliability": "best_effort", "durability": "transient_local", "depth": 1},
    )
    assert (m.period_ms, m.lease_ms) == (250, 60_000)
    assert m.qos_text == "2:1:,1:,:,:,,"
    assert mapping().qos_text is None


def test_uplink_config_names_the_yaml_path_and_refuses_duplicate_names(tmp_path: Path) -> None:
    path = tmp_path / "uplink.yaml"
    path.write_text(
        "kafka: {bootstrap_servers: b}\nregistry: {url: r}\ncommands:\n"
        "  - {name: a, from: t1, to: '/{key}/x', type: p/msg/T}\n"
        "  - name: b\n    from: t2\n    to: '/{key}/y'\n    type: p/msg/T\n    repeat: {lease: never}\n"
    )
    with pytest.raises(ConfigError, match=r"commands\[1\]\.repeat\.lease \(line 9\): .*invalid duration"):
        load_config(UplinkConfig, path)
    path.write_text(
        "kafka: {bootstrap_servers: b}\nregistry: {url: r}\ncommands:\n"
        "  - {name: a, from: t1, to: '/{key}/x', type: p/msg/T}\n"
        "  - {name: a, from: t2, to: '/{key}/y', type: p/msg/T}\n"
    )
    with pytest.raises(ConfigError, match="two command mappings are named 'a'"):
        load_config(UplinkConfig, path)
