"""fleetlink.console.forms: the mapping form -> the admin request body; problems -> form fields."""

from __future__ import annotations

from typing import Any

import pytest

from fleetlink.console.errors import FormError
from fleetlink.console.forms import (
    MappingForm,
    field_errors,
    field_of,
    mapping_body,
    parse_stages,
    refusal_fields,
)


def form(**values: str) -> MappingForm:
    return MappingForm.model_validate(values)


@pytest.mark.parametrize(
    ("values", "with_name", "expected"),
    [
        ({}, True, {}),
        (
            {"name": " imu ", "from": "/{robot}/imu", "to": "fleet.imu"},
            True,
            {"name": "imu", "from": "/{robot}/imu", "to": "fleet.imu"},
        ),
        # empty inputs are left out: the edge's defaults and "required" messages apply
        (
            {"name": "imu", "robot_type": "", "key": "  ", "type": "", "delivery": "", "stages": "\n"},
            True,
            {"name": "imu"},
        ),
        (
            {
                "name": "imu",
                "robot_type": "tb4",
                "key": "{robot}",
                "type": "sensor_msgs/msg/Imu",
                "delivery": "best_effort",
            },
            True,
            {
                "name": "imu",
                "robot_type": "tb4",
                "key": "{robot}",
                "type": "sensor_msgs/msg/Imu",
                "delivery": "best_effort",
            },
        ),
        (
            {"name": "imu", "stages": "- {type: throttle, hz: 2}\n- type: project\n  fields: [a]"},
            True,
            {"name": "imu", "stages": [{"type": "throttle", "hz": 2}, {"type": "project", "fields": ["a"]}]},
        ),
        (
            {"name": "imu", "stages": '[{"type": "throttle", "hz": 2}]'},
            True,
            {"name": "imu", "stages": [{"type": "throttle", "hz": 2}]},
        ),
        ({"name": "imu", "to": "fleet.imu"}, False, {"to": "fleet.imu"}),
        ({"stages": "# nothing yet"}, True, {}),
    ],
)
def test_mapping_body(values: dict[str, str], with_name: bool, expected: dict[str, Any]) -> None:
    assert mapping_body(form(**values), with_name=with_name) == expected


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("- {type: throttle, hz: 2", "not valid YAML (line 1, column 25): expected ',' or '}'"),
        ("type: throttle", "a list of stages is expected"),
        ("throttle", "a list of stages is expected"),
        ("- [unclosed", "not valid YAML"),
    ],
)
def test_stages_that_do_not_parse_name_the_stages_field(text: str, message: str) -> None:
    with pytest.raises(FormError) as caught:
        parse_stages(text)
    assert list(caught.value.fields) == ["stages"]
    assert caught.value.fields["stages"][0].startswith(message)
    assert "stages:" in str(caught.value)


def test_the_form_refuses_unknown_inputs() -> None:
    with pytest.raises(ValueError, match="extra"):
        MappingForm.model_validate({"name": "x", "evil": "1"})


@pytest.mark.parametrize(
    ("path", "field"),
    [
        ("from", "from"),
        ("to", "to"),
        ("name", "name"),
        ("key", "key"),
        ("type", "type"),
        ("robot_type", "robot_type"),
        ("delivery", "delivery"),
        ("stages", "stages"),
        ("stages[1].hz", "stages"),
        ("stages[0]", "stages"),
        ("stages.0.hz", "stages"),
        ("<root>", "_form"),
        ("", "_form"),
        ("mappings[3].to", "mappings"),
        ("stagez[3].to", "_form"),
        ("fromage", "_form"),
    ],
)
def test_field_of(path: str, field: str) -> None:
    assert field_of(path) == field


def test_field_errors_put_each_problem_on_its_field() -> None:
    problems = [
        {"path": "from", "message": "a topic pattern starts with '/'"},
        {"path": "stages[1].hz", "message": "Input should be greater than 0"},
        {"path": "stages[0].keep", "message": "Input should be 'latest' or 'first'"},
        {"path": "<root>", "message": "the mapping table refused the change"},
        {"message": "no path at all"},
    ]
    assert field_errors(problems) == {
        "from": ["a topic pattern starts with '/'"],
        "stages": [
            "stages[1].hz: Input should be greater than 0",
            "stages[0].keep: Input should be 'latest' or 'first'",
        ],
        "_form": ["<root>: the mapping table refused the change", "<root>: no path at all"],
    }


@pytest.mark.parametrize(
    ("status", "error", "problems", "expected"),
    [
        (409, "a mapping named 'ir' exists already", [], {"name": ["a mapping named 'ir' exists already"]}),
        (404, "no mapping named 'x'", [], {"_form": ["no mapping named 'x'"]}),
        (504, None, [], {"_form": ["refused (504)"]}),
        (422, "invalid", [{"path": "to", "message": "bad"}], {"to": ["bad"]}),
    ],
)
def test_refusal_fields(
    status: int, error: str | None, problems: list[dict[str, Any]], expected: dict[str, list[str]]
) -> None:
    assert refusal_fields(status, error, problems) == expected
