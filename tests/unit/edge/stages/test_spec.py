"""The YAML shape of stages: what is accepted, what is refused and how errors read."""

from __future__ import annotations

from typing import Any

import pytest
import yaml
from pydantic import BaseModel, ConfigDict, TypeAdapter, ValidationError

from fleetlink.common.configfile import validate_data
from fleetlink.common.errors import ConfigError
from fleetlink.edge.stages import (
    AggregateSpec,
    FilterSpec,
    OnChangeSpec,
    ProjectSpec,
    StageSpec,
    ThrottleSpec,
)

BRIEF_YAML = """
stages:
  - {type: filter, expr: "kidnap.is_kidnapped == true || data.size() > 3"}
  - {type: throttle, hz: 10, keep: latest}
  - {type: on_change, fields: [pose.pose.position.x], deadband: 0.05, heartbeat: 5s}
  - {type: project, fields: [header.stamp, twist.twist.linear.x]}
  - {type: aggregate, window: 1s, hop: 1s, fields: [linear_acceleration.x, angular_velocity.z],
     ops: [count, mean, min, max, last, stddev], allowed_lateness: 0s}
"""


class Mapping(BaseModel):
    """Stands in for the edge config's mapping model, which embeds the stage list like this."""

    model_config = ConfigDict(extra="forbid")
    stages: list[StageSpec] = []


def test_the_documented_example_parses() -> None:
    mapping = Mapping.model_validate(yaml.safe_load(BRIEF_YAML))
    f, t, c, p, a = mapping.stages
    assert isinstance(f, FilterSpec)
    assert f.expr.startswith("kidnap")
    assert isinstance(t, ThrottleSpec)
    assert (t.hz, t.keep) == (10, "latest")
    assert isinstance(c, OnChangeSpec)
    assert (c.fields, c.deadband, c.heartbeat) == (["pose.pose.position.x"], 0.05, 5_000_000_000)
    assert isinstance(p, ProjectSpec)
    assert p.flatten is False
    assert isinstance(a, AggregateSpec)
    assert (a.window, a.hop, a.allowed_lateness, a.idle_timeout) == (10**9, 10**9, 0, None)
    assert a.ops == ["count", "mean", "min", "max", "last", "stddev"]


def test_dump_and_load_round_trip_with_duration_text() -> None:
    mapping = Mapping.model_validate(yaml.safe_load(BRIEF_YAML))
    dumped = mapping.model_dump(mode="json", exclude_none=True)
    assert dumped["stages"][2]["heartbeat"] == "5s"
    assert dumped["stages"][4]["window"] == "1s"
    assert Mapping.model_validate(yaml.safe_load(yaml.safe_dump(dumped))) == mapping
    assert Mapping.model_validate_json(mapping.model_dump_json()) == mapping


def test_json_schema_is_available_for_the_admin_api() -> None:
    schema = TypeAdapter(list[StageSpec]).json_schema()
    text = str(schema)
    for kind in ("filter", "throttle", "on_change", "project", "aggregate"):
        assert f"'{kind}'" in text
    assert "discriminator" in text


@pytest.mark.parametrize(
    ("stage", "fragment"),
    [
        ({"type": "sample"}, "does not match any of the expected tags"),
        ({"expr": "x > 1"}, "Unable to extract tag using discriminator 'type'"),
        ({"type": "filter", "expr": "x > 1", "exprs": 1}, "stages[0].filter.exprs: unknown key"),
        ({"type": "filter", "expr": "x >"}, "invalid filter expression: column 4: expected a value"),
        ({"type": "filter", "expr": "x + 1"}, "must be a condition"),
        ({"type": "filter", "expr": ""}, "at least 1 character"),
        ({"type": "throttle", "hz": 0}, "stages[0].throttle.hz: Input should be greater than 0"),
        ({"type": "throttle", "hz": "10"}, "stages[0].throttle.hz: Input should be a valid number"),
        ({"type": "throttle", "hz": True}, "stages[0].throttle.hz: Input should be a valid number"),
        ({"type": "throttle", "hz": 10, "keep": "last"}, "Input should be 'latest' or 'first'"),
        ({"type": "throttle"}, "stages[0].throttle.hz: Field required"),
        ({"type": "on_change", "fields": []}, "List should have at least 1 item"),
        ({"type": "on_change", "fields": ["x"], "deadband": -1}, "greater than or equal to 0"),
        ({"type": "on_change", "fields": ["x"], "deadband": float("nan")}, "finite number"),
        ({"type": "on_change", "fields": ["x"], "heartbeat": "0s"}, "heartbeat must be longer than 0s"),
        ({"type": "on_change", "fields": ["x"], "heartbeat": "soon"}, "invalid duration 'soon'"),
        ({"type": "on_change", "fields": ["x..y"]}, "invalid field path 'x..y'"),
        ({"type": "project", "fields": ["a", "a"]}, "listed more than once"),
        ({"type": "project", "fields": "a"}, "Input should be a valid list"),
        (
            {"type": "aggregate", "window": "1s", "fields": ["x"], "ops": ["median"]},
            "Input should be 'count'",
        ),
        ({"type": "aggregate", "window": "1s", "fields": ["x"], "ops": ["mean", "mean"]}, "more than once"),
        ({"type": "aggregate", "window": "0s", "fields": ["x"], "ops": ["mean"]}, "window must be longer"),
        (
            {"type": "aggregate", "window": "1s", "hop": "2s", "fields": ["x"], "ops": ["mean"]},
            "at most the window",
        ),
        (
            {"type": "aggregate", "window": "1s", "fields": ["x"], "ops": ["mean"], "idle_timeout": 0},
            "idle_timeout",
        ),
        ({"type": "aggregate", "window": "1s", "fields": ["x"]}, "stages[0].aggregate.ops: Field required"),
        ({"type": "filter", "expr": "x > 1", "name": "has space"}, "must be one key chunk"),
    ],
)
def test_refused_with_the_yaml_path(stage: dict[str, Any], fragment: str) -> None:
    with pytest.raises(ConfigError) as info:
        validate_data(Mapping, {"stages": [stage]}, source="agent.yaml")
    assert fragment in str(info.value)
    assert "agent.yaml" in str(info.value)


@pytest.mark.parametrize(
    ("stage", "attr", "value"),
    [
        ({"type": "aggregate", "window": 2, "fields": ["x"], "ops": ["mean"]}, "window", 2 * 10**9),
        ({"type": "aggregate", "window": 0.25, "fields": ["x"], "ops": ["mean"]}, "window", 250_000_000),
        ({"type": "aggregate", "window": "2m", "fields": ["x"], "ops": ["mean"]}, "window", 120 * 10**9),
        ({"type": "throttle", "hz": 2.5}, "hz", 2.5),
        ({"type": "throttle", "hz": 10}, "keep", "latest"),
        ({"type": "on_change", "fields": ["x"]}, "heartbeat", None),
        ({"type": "project", "fields": ["ranges[0]"], "flatten": True}, "flatten", True),
    ],
)
def test_accepted_values(stage: dict[str, Any], attr: str, value: Any) -> None:
    adapter: TypeAdapter[Any] = TypeAdapter(StageSpec)
    spec = adapter.validate_python(stage)
    assert getattr(spec, attr) == value


def test_specs_are_immutable() -> None:
    spec = ThrottleSpec(type="throttle", hz=5)
    with pytest.raises(ValidationError):
        spec.hz = 6
