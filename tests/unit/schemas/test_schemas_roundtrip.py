"""CDR -> Avro -> CDR is byte-identical, and decode() equals rosbags' decoding.

Values are generated with hypothesis for every message type of the jazzy store (plus the
iRobot Create 3 package), serialised with rosbags, converted and compared byte for byte.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rosbags.interfaces import Nodetype
from rosbags.typesys.store import Typestore

from schemas.codec import get_codec
from schemas.layout import RANGES
from schemas.typestore import load_typestore, message_types

IROBOT = Path(__file__).resolve().parents[4] / "shared" / "data" / "msgs" / "irobot_create_msgs"
TS = load_typestore("jazzy", msg_paths=[IROBOT])
TYPES = message_types(TS)

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


def test_every_type_is_covered() -> None:
    assert len(TYPES) > 180
    assert "sensor_msgs/msg/PointCloud2" in TYPES
    assert "irobot_create_msgs/msg/LightringLeds" in TYPES


@pytest.mark.parametrize("typename", TYPES)
@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_round_trip(typename: str, data: st.DataObject) -> None:
    obj = data.draw(message(TS, typename))
    cdr = bytes(TS.serialize_cdr(obj, typename))
    codec = get_codec(TS, typename, "jazzy")
    avro = codec.cdr_to_avro(cdr)
    assert codec.avro_to_cdr(avro) == cdr
    # the Avro body is exactly what fastavro writes for the decoded datum
    decoded = codec.decode(cdr)
    assert codec.encode_datum(decoded) == avro
    assert same(decoded, avro_shaped(TS, TS.deserialize_cdr(cdr, typename), typename))
    # big-endian input gives the same record
    big = bytes(TS.serialize_cdr(obj, typename, little_endian=False))
    assert codec.cdr_to_avro(big) == avro
