"""Value generators and comparisons shared by the schemas tests.

``message(ts, typename)`` is a hypothesis strategy for rosbags message objects of any type;
``avro_shaped`` turns rosbags' decoded object into what an Avro reader returns; ``same``
compares such values treating NaN as equal to NaN.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from hypothesis import strategies as st
from rosbags.interfaces import Nodetype
from rosbags.typesys.store import Typestore

from fleetlink.schemas.layout import RANGES

_DTYPES = {
    "bool": np.bool_,
    "byte": np.int8,
    "char": np.uint8,
    "int8": np.int8,
    "uint8": np.uint8,
    "int16": np.int16,
    "uint16": np.uint16,
    "int32": np.int32,
    "uint32": np.uint32,
    "int64": np.int64,
    "uint64": np.uint64,
    "float32": np.float32,
    "float64": np.float64,
}
_TEXT = st.text(st.characters(codec="utf-8"), max_size=12)


def _scalar(kind: str, bound: int) -> st.SearchStrategy[Any]:
    if kind == "string":
        if bound:
            return _TEXT.filter(lambda s: len(s.encode()) <= bound)
        return _TEXT
    if kind == "bool":
        return st.booleans()
    if kind == "float32":
        return st.floats(width=32)
    if kind == "float64":
        return st.floats()
    if kind == "byte":  # rosbags packs scalar byte as a signed char
        return st.integers(-128, 127)
    lo, hi = RANGES[kind]
    return st.integers(lo, hi)


def _field(ts: Typestore, desc: Any) -> st.SearchStrategy[Any]:
    if desc[0] == Nodetype.BASE:
        return _scalar(*desc[1])
    if desc[0] == Nodetype.NAME:
        return message(ts, desc[1])
    inner, size = desc[1]
    fixed = desc[0] == Nodetype.ARRAY
    lo, hi = (size, size) if fixed else (0, size or 4)
    if inner[0] == Nodetype.BASE and inner[1][0] != "string":
        kind = inner[1][0]
        dtype = _DTYPES[kind]

        def to_array(xs: list[Any]) -> Any:
            return np.array(xs, dtype=dtype)

        return st.lists(_scalar(kind, 0), min_size=lo, max_size=hi).map(to_array)
    return st.lists(_field(ts, inner), min_size=lo, max_size=hi)


def message(ts: Typestore, typename: str) -> st.SearchStrategy[Any]:
    cls = ts.types[typename]
    fields = ts.fielddefs[typename][1]
    return st.builds(cls, *[_field(ts, desc) for _, desc in fields])


def avro_shaped(ts: Typestore, obj: Any, typename: str) -> dict[str, Any]:
    """rosbags' decoded object in the shape an Avro reader returns."""
    out: dict[str, Any] = {}
    for name, desc in ts.fielddefs[typename][1]:
        value = getattr(obj, name if hasattr(obj, name) else f"{name}_")
        out[name] = _shaped(ts, value, desc)
    return out


def _shaped(ts: Typestore, value: Any, desc: Any) -> Any:
    if desc[0] == Nodetype.BASE:
        return value & 0xFF if desc[1][0] == "byte" else value
    if desc[0] == Nodetype.NAME:
        return avro_shaped(ts, value, desc[1])
    inner = desc[1][0]
    if inner[0] == Nodetype.BASE and inner[1][0] in ("uint8", "byte", "char"):
        return bytes(np.asarray(value).view(np.uint8))
    if inner[0] == Nodetype.BASE and inner[1][0] != "string":
        return np.asarray(value).tolist()
    return [_shaped(ts, v, inner) for v in value]


def same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or a == b
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    return bool(a == b) and type(a) is type(b)
