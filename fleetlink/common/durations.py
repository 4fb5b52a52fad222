"""Durations in every config: ``"250ms"``, ``"1s"``, ``"2m"``, ``"1.5h"`` or a number of seconds.

Parsed once into integer nanoseconds; ``format_duration`` writes the shortest exact text back,
so a config that is validated and saved again reads the same. ``DurationNs`` holds
nanoseconds, ``Seconds`` a float number of seconds, ``parse_duration_ms`` whole milliseconds.
"""

from __future__ import annotations

import math
import re
from decimal import Decimal, InvalidOperation
from typing import Annotated, Any

from pydantic import BeforeValidator, Field, PlainSerializer, WithJsonSchema

UNITS_NS: dict[str, int] = {
    "ns": 1,
    "us": 1_000,
    "ms": 1_000_000,
    "s": 1_000_000_000,
    "m": 60_000_000_000,
    "h": 3_600_000_000_000,
}

DURATION_PATTERN = r"^\s*(\d+(\.\d*)?|\.\d+)\s*(ns|us|ms|s|m|h)\s*$"
_DURATION_RE = re.compile(DURATION_PATTERN)


def parse_duration(value: object) -> int:
    """Duration text or seconds -> nanoseconds (``int``, >= 0). Raises ``ValueError``."""
    if isinstance(value, bool):
        raise ValueError("a duration must be text such as '250ms' or '1s', or a number of seconds")
    if isinstance(value, int):
        seconds = Decimal(value)
    elif isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"duration must be finite, got {value!r}")
        seconds = Decimal(repr(value))
    elif isinstance(value, str):
        match = _DURATION_RE.match(value)
        if match is None:
            raise ValueError(
                f"invalid duration {value!r}: use a number with a unit (ns, us, ms, s, m, h), e.g. '250ms'"
            )
        try:
            ns = Decimal(match.group(1)) * UNITS_NS[match.group(3)]
        except InvalidOperation:  # pragma: no cover - the regex only lets decimals through
            raise ValueError(f"invalid duration {value!r}") from None
        return _whole_ns(ns, value)
    else:
        raise ValueError("a duration must be text such as '250ms' or '1s', or a number of seconds")
    if seconds < 0:
        raise ValueError(f"duration must not be negative, got {value!r}")
    return _whole_ns(seconds * UNITS_NS["s"], value)


def _whole_ns(ns: Decimal, original: object) -> int:
    if ns != ns.to_integral_value():
        raise ValueError(f"duration {original!r} is not a whole number of nanoseconds")
    return int(ns)


def format_duration(ns: int) -> str:
    """Nanoseconds -> the largest unit that states it exactly (``1_500_000_000`` -> ``"1500ms"``)."""
    if ns == 0:
        return "0s"
    for unit in ("h", "m", "s", "ms", "us"):
        if ns % UNITS_NS[unit] == 0:
            return f"{ns // UNITS_NS[unit]}{unit}"
    return f"{ns}ns"


_JSON_SCHEMA: dict[str, Any] = {
    "anyOf": [
        {"type": "string", "pattern": DURATION_PATTERN},
        {"type": "number", "minimum": 0},
    ],
    "description": "a duration: text with a unit (ns, us, ms, s, m, h) such as '250ms', or seconds",
}

DurationNs = Annotated[
    int,
    BeforeValidator(parse_duration),
    PlainSerializer(format_duration, return_type=str),
    WithJsonSchema(_JSON_SCHEMA),
]
"""A pydantic field type: accepts duration text or seconds, holds nanoseconds, dumps text."""


def parse_duration_ms(value: object) -> int:
    """Duration text or seconds -> a positive whole number of milliseconds. Raises ``ValueError``."""
    ns = parse_duration(value)
    if ns < UNITS_NS["ms"] or ns % UNITS_NS["ms"]:
        raise ValueError(f"duration {value!r} must be a whole, positive number of milliseconds")
    return ns // UNITS_NS["ms"]


Seconds = Annotated[
    float,
    BeforeValidator(lambda value: parse_duration(value) / UNITS_NS["s"]),
    PlainSerializer(lambda seconds: format_duration(round(seconds * UNITS_NS["s"])), return_type=str),
    WithJsonSchema(_JSON_SCHEMA),
]
"""A pydantic field type: accepts duration text or seconds, holds float seconds, dumps text."""

PositiveSeconds = Annotated[Seconds, Field(gt=0)]
"""A positive duration in seconds, written as ``"1s"``, ``"500ms"`` … in YAML."""
