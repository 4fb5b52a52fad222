"""Field path syntax and getters."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from fleetlink.edge.stages.errors import FieldPathError
from fleetlink.edge.stages.paths import Steps, field_name, make_getter, parse_path, path_text


@pytest.mark.parametrize(
    ("text", "steps"),
    [
        ("x", ("x",)),
        ("twist.twist.linear.x", ("twist", "twist", "linear", "x")),
        ("ranges[0]", ("ranges", 0)),
        ("ranges[-1]", ("ranges", -1)),
        ("a[1][2].b", ("a", 1, 2, "b")),
        ("_private.f2", ("_private", "f2")),
    ],
)
def test_parse_and_print(text: str, steps: Steps) -> None:
    assert parse_path(text) == steps
    assert path_text(steps) == text


@pytest.mark.parametrize(
    ("text", "column"),
    [("", 1), (".x", 1), ("x.", 3), ("x..y", 3), ("x[a]", 2), ("x[1", 2), ("1x", 1), ("x y", 2), ("x-y", 2)],
)
def test_parse_errors_name_the_column(text: str, column: int) -> None:
    with pytest.raises(FieldPathError, match=f"column {column}") as info:
        parse_path(text)
    assert info.value.path == text


@pytest.mark.parametrize(
    ("text", "name"),
    [
        ("twist.twist.linear.x", "twist_twist_linear_x"),
        ("ranges[0]", "ranges_0"),
        ("ranges[-2]", "ranges_m2"),
    ],
)
def test_field_name(text: str, name: str) -> None:
    assert field_name(parse_path(text)) == name


VALUE: dict[str, Any] = {
    "a": {"b": {"c": {"d": {"e": 5}}}},
    "ranges": np.array([0.5, 1.5], dtype=np.float32),
    "items": [{"v": 1}, {"v": 2}],
    "data": b"\x07\x08",
}


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("a.b.c.d.e", 5),
        ("a.b.c.d", {"e": 5}),
        ("a.b", {"c": {"d": {"e": 5}}}),
        ("ranges[1]", 1.5),
        ("ranges[-1]", 1.5),
        ("items[0].v", 1),
        ("data[1]", 8),
    ],
)
def test_getter(text: str, expected: Any) -> None:
    got = make_getter(parse_path(text))(VALUE)
    assert got == expected
    assert not isinstance(got, np.generic)  # numpy scalars come back as Python numbers


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ("missing", KeyError),
        ("a.x", KeyError),
        ("ranges[5]", IndexError),
        ("items[0][0]", TypeError),
        ("data.x", TypeError),
        ("a[0]", TypeError),
        ("a.b.c.d.e.f", TypeError),
    ],
)
def test_getter_raises_lookup_or_type_errors(text: str, error: type[Exception]) -> None:
    with pytest.raises(error):
        make_getter(parse_path(text))(VALUE)
