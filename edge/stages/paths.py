"""Field paths into decoded messages: ``twist.twist.linear.x``, ``ranges[0]``, ``ranges[-1]``.

A path is parsed once into steps (``str`` for a record field, ``int`` for an array index) and
compiled into a getter. Getters raise ``LookupError``/``TypeError`` for a value that does not
have the path; callers that handle one sample at a time catch and count those.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from fleetlink.edge.stages.errors import FieldPathError

Step = str | int
Steps = tuple[Step, ...]
Getter = Callable[[Any], Any]
"""value -> the value at a path; the argument is a decoded message (a mapping)."""

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_INDEX = re.compile(r"\[(-?\d+)\]")


def parse_path(text: str) -> Steps:
    """``"a.b[2].c"`` -> ``("a", "b", 2, "c")``; raises ``FieldPathError`` naming the column."""
    steps: list[Step] = []
    pos = 0
    expect_name = True
    while pos < len(text) or expect_name:
        if expect_name:
            match = _IDENT.match(text, pos)
            if match is None:
                found = repr(text[pos]) if pos < len(text) else "end of path"
                raise FieldPathError(
                    f"invalid field path {text!r}: expected a field name at column {pos + 1}, found {found}",
                    path=text,
                )
            steps.append(match.group())
            pos = match.end()
            expect_name = False
        elif text[pos] == ".":
            pos += 1
            expect_name = True
        else:
            index = _INDEX.match(text, pos)
            if index is None:
                raise FieldPathError(
                    f"invalid field path {text!r}: expected '.' or '[index]' at column {pos + 1}, "
                    f"found {text[pos]!r}",
                    path=text,
                )
            steps.append(int(index.group(1)))
            pos = index.end()
    return tuple(steps)


def path_text(steps: Sequence[Step]) -> str:
    """Inverse of ``parse_path``."""
    out = ""
    for step in steps:
        if isinstance(step, int):
            out += f"[{step}]"
        else:
            out += f".{step}" if out else step
    return out


def field_name(steps: Sequence[Step]) -> str:
    """A path as one Avro field name: dots and brackets become ``_`` (``ranges[-1]`` -> ``ranges_m1``)."""
    parts = [step if isinstance(step, str) else (str(step) if step >= 0 else f"m{-step}") for step in steps]
    return "_".join(parts)


def plain(value: Any) -> Any:
    """numpy scalars -> the Python scalar of the same value; anything else unchanged."""
    if isinstance(value, np.generic):
        return value.item()
    return value


def make_getter(steps: Steps) -> Getter:
    """A fast function ``value -> value at path`` (numpy scalars returned as Python scalars)."""
    has_index = any(isinstance(step, int) for step in steps)
    if not has_index and len(steps) == 1:
        (a,) = steps
        return lambda v: v[a]
    if not has_index and len(steps) == 2:
        a, b = steps
        return lambda v: v[a][b]
    if not has_index and len(steps) == 3:
        a, b, c = steps
        return lambda v: v[a][b][c]
    if not has_index and len(steps) == 4:
        a, b, c, d = steps
        return lambda v: v[a][b][c][d]

    def get(v: Any) -> Any:
        for step in steps:
            if isinstance(step, int) and isinstance(v, Mapping):
                raise TypeError(f"cannot index a record with [{step}]")
            if isinstance(step, str) and not isinstance(v, Mapping):
                raise TypeError(f"field {step!r} of a {type(v).__name__}, not of a record")
            v = v[step]
        return plain(v)

    return get
