"""Duration text and numbers -> nanoseconds, and back."""

from __future__ import annotations

import pytest
from pydantic import BaseModel, ValidationError

from fleetlink.common.durations import DurationNs, format_duration, parse_duration


@pytest.mark.parametrize(
    ("text", "ns"),
    [
        ("250ms", 250_000_000),
        ("1s", 1_000_000_000),
        ("2m", 120_000_000_000),
        ("1h", 3_600_000_000_000),
        ("1.5s", 1_500_000_000),
        (".5s", 500_000_000),
        ("10us", 10_000),
        ("7ns", 7),
        (" 3 s ", 3_000_000_000),
        ("0s", 0),
        (2, 2_000_000_000),
        (0.1, 100_000_000),
        (0, 0),
        (1e-9, 1),
    ],
)
def test_parse(text: object, ns: int) -> None:
    assert parse_duration(text) == ns


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("1", "use a number with a unit"),
        ("1 sec", "use a number with a unit"),
        ("-1s", "use a number with a unit"),
        ("1.5ns", "not a whole number of nanoseconds"),
        (-1, "must not be negative"),
        (float("inf"), "must be finite"),
        (float("nan"), "must be finite"),
        (True, "a duration must be text"),
        (None, "a duration must be text"),
        ([1], "a duration must be text"),
    ],
)
def test_parse_rejects(text: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        parse_duration(text)


@pytest.mark.parametrize(
    ("ns", "text"),
    [
        (0, "0s"),
        (1, "1ns"),
        (1_000, "1us"),
        (250_000_000, "250ms"),
        (1_500_000_000, "1500ms"),
        (60_000_000_000, "1m"),
        (7_200_000_000_000, "2h"),
        (90_000_000_000, "90s"),
    ],
)
def test_format_round_trips(ns: int, text: str) -> None:
    assert format_duration(ns) == text
    assert parse_duration(text) == ns


class _Model(BaseModel):
    window: DurationNs


def test_pydantic_field_parses_and_dumps_text() -> None:
    model = _Model.model_validate({"window": "250ms"})
    assert model.window == 250_000_000
    assert model.model_dump() == {"window": "250ms"}
    assert _Model.model_validate(model.model_dump()) == model
    schema = _Model.model_json_schema()["properties"]["window"]
    assert {alt["type"] for alt in schema["anyOf"]} == {"string", "number"}
    with pytest.raises(ValidationError, match="invalid duration"):
        _Model.model_validate({"window": "soon"})
