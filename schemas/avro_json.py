"""Avro datums ↔ JSON-ready values, for people reading and writing records (``fleetlink kafka``).

Reading (:func:`to_json`) needs no schema: records are objects, arrays lists, ``bytes`` and
``fixed`` base64 strings, non-finite floats the strings ``"NaN"``, ``"Infinity"``,
``"-Infinity"``; unions show their value alone. Writing (:func:`from_json`) follows the schema,
so the same text goes back: base64 (or a list of 0-255 integers) for ``bytes``, the three
strings for non-finite floats, defaults for missing fields that have one, and every mistake
named by its path (``leds[2].red: expected an int, got 'x'``). Pure: no I/O.
"""

from __future__ import annotations

import base64
import binascii
import datetime
import decimal
import math
import uuid
from collections.abc import Mapping
from typing import Any

from fleetlink.schemas.errors import EncodeError

__all__ = ["from_json", "to_json"]

_NON_FINITE = {"NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}
_PRIMITIVES = {"null", "boolean", "int", "long", "float", "double", "bytes", "string"}
_INT_RANGE = {"int": (-(2**31), 2**31 - 1), "long": (-(2**63), 2**63 - 1)}


def to_json(datum: Any) -> Any:  # noqa: PLR0911 - one return per kind of value
    """A decoded Avro datum as plain JSON values (see the module docstring)."""
    if isinstance(datum, Mapping):
        return {str(k): to_json(v) for k, v in datum.items()}
    if isinstance(datum, list | tuple):
        return [to_json(v) for v in datum]
    if isinstance(datum, bytes | bytearray | memoryview):
        return base64.b64encode(bytes(datum)).decode("ascii")
    if isinstance(datum, float) and not math.isfinite(datum):
        return "NaN" if math.isnan(datum) else ("Infinity" if datum > 0 else "-Infinity")
    if isinstance(datum, datetime.datetime | datetime.date | datetime.time):
        return datum.isoformat()
    if isinstance(datum, decimal.Decimal | uuid.UUID):
        return str(datum)
    return datum


class _MismatchError(Exception):
    def __init__(self, path: str, reason: str) -> None:
        super().__init__(path, reason)
        self.path = path
        self.reason = reason


def from_json(schema: Any, value: Any) -> Any:
    """The Avro datum of ``schema`` (its parsed JSON) that ``value`` describes; raises EncodeError."""
    names: dict[str, Any] = {}
    _collect(schema, None, names)
    try:
        return _convert(schema, value, "", None, names)
    except _MismatchError as exc:
        where = f"{exc.path}: " if exc.path else ""
        raise EncodeError(_name_of(schema), f"{where}{exc.reason}") from None


def _name_of(schema: Any) -> str:
    if isinstance(schema, Mapping):
        name = str(schema.get("name", schema.get("type", "?")))
        namespace = schema.get("namespace")
        return f"{namespace}.{name}" if namespace and "." not in name else name
    return str(schema)


def _full(name: str, namespace: str | None) -> str:
    return name if "." in name or not namespace else f"{namespace}.{name}"


def _collect(schema: Any, namespace: str | None, names: dict[str, Any]) -> None:
    """Every named type (record, enum, fixed) by its full name, for references by name."""
    if isinstance(schema, list):
        for branch in schema:
            _collect(branch, namespace, names)
        return
    if not isinstance(schema, Mapping):
        return
    kind = schema.get("type")
    if kind in ("record", "error", "enum", "fixed"):
        full = _full(str(schema["name"]), schema.get("namespace", namespace))
        names[full] = schema
        namespace = full.rpartition(".")[0] or None
        for field in schema.get("fields", []) if kind != "enum" else []:
            _collect(field["type"], namespace, names)
    elif kind == "array":
        _collect(schema["items"], namespace, names)
    elif kind == "map":
        _collect(schema["values"], namespace, names)
    elif isinstance(kind, list | Mapping):
        _collect(kind, namespace, names)


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _convert(schema: Any, value: Any, path: str, namespace: str | None, names: dict[str, Any]) -> Any:  # noqa: PLR0911, PLR0912 - one branch per Avro type
    if isinstance(schema, list):
        return _union(schema, value, path, namespace, names)
    if isinstance(schema, str):
        if schema in _PRIMITIVES:
            return _primitive(schema, value, path)
        named = names.get(_full(schema, namespace)) or names.get(schema)
        if named is None:
            raise _MismatchError(path, f"unknown type {schema!r}")
        return _convert(named, value, path, namespace, names)
    kind = schema.get("type")
    if kind in _PRIMITIVES:
        return _primitive(kind, value, path)
    if kind in ("record", "error"):
        full = _full(str(schema["name"]), schema.get("namespace", namespace))
        return _record(schema, value, path, full.rpartition(".")[0] or None, names)
    if kind == "enum":
        if value not in schema.get("symbols", []):
            raise _MismatchError(path, f"expected one of {schema.get('symbols')}, got {_show(value)}")
        return value
    if kind == "fixed":
        raw = _bytes(value, path)
        if len(raw) != schema["size"]:
            raise _MismatchError(path, f"expected {schema['size']} bytes, got {len(raw)}")
        return raw
    if kind == "array":
        if not isinstance(value, list):
            raise _MismatchError(path, f"expected a list, got {_show(value)}")
        return [_convert(schema["items"], v, f"{path}[{i}]", namespace, names) for i, v in enumerate(value)]
    if kind == "map":
        if not isinstance(value, Mapping):
            raise _MismatchError(path, f"expected a mapping, got {_show(value)}")
        return {
            str(k): _convert(schema["values"], v, f"{path}.{k}", namespace, names) for k, v in value.items()
        }
    if isinstance(kind, list | Mapping | str):
        return _convert(kind, value, path, namespace, names)
    raise _MismatchError(path, f"unsupported schema {_show(schema)}")


def _record(
    schema: Mapping[str, Any], value: Any, path: str, namespace: str | None, names: dict[str, Any]
) -> Any:
    if not isinstance(value, Mapping):
        raise _MismatchError(path, f"expected a mapping (record {schema['name']}), got {_show(value)}")
    fields = schema.get("fields", [])
    unknown = sorted(set(map(str, value)) - {f["name"] for f in fields})
    if unknown:
        raise _MismatchError(
            path, f"unknown field(s) {unknown}; {schema['name']} has {[f['name'] for f in fields]}"
        )
    out = {}
    for field in fields:
        name = field["name"]
        where = f"{path}.{name}" if path else name
        if name in value:
            out[name] = _convert(field["type"], value[name], where, namespace, names)
        elif "default" in field:
            out[name] = _convert(field["type"], field["default"], where, namespace, names)
        else:
            raise _MismatchError(where, "missing (the field has no default)")
    return out


def _union(branches: list[Any], value: Any, path: str, namespace: str | None, names: dict[str, Any]) -> Any:
    reasons = []
    for branch in branches:
        try:
            return _convert(branch, value, path, namespace, names)
        except _MismatchError as exc:
            reasons.append(exc.reason)
    raise _MismatchError(path, f"matches no branch of the union: {'; '.join(reasons)}")


def _primitive(kind: str, value: Any, path: str) -> Any:  # noqa: PLR0911 - one return per primitive
    if kind == "null":
        if value is not None:
            raise _MismatchError(path, f"expected null, got {_show(value)}")
        return None
    if kind == "boolean":
        if not isinstance(value, bool):
            raise _MismatchError(path, f"expected true or false, got {_show(value)}")
        return value
    if kind in _INT_RANGE:
        if isinstance(value, bool) or not isinstance(value, int):
            raise _MismatchError(path, f"expected an {kind}, got {_show(value)}")
        low, high = _INT_RANGE[kind]
        if not low <= value <= high:
            raise _MismatchError(path, f"{value} does not fit an Avro {kind}")
        return value
    if kind in ("float", "double"):
        if isinstance(value, str) and value in _NON_FINITE:
            return _NON_FINITE[value]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise _MismatchError(path, f"expected a number (or NaN, Infinity, -Infinity), got {_show(value)}")
        return float(value)
    if kind == "bytes":
        return _bytes(value, path)
    if not isinstance(value, str):
        raise _MismatchError(path, f"expected a string, got {_show(value)} (quote it in YAML)")
    return value


def _bytes(value: Any, path: str) -> bytes:
    if isinstance(value, bytes | bytearray):
        return bytes(value)
    if isinstance(value, str):
        try:
            return base64.b64decode(value, validate=True)
        except (binascii.Error, ValueError):
            raise _MismatchError(path, f"expected base64 bytes, got {_show(value)}") from None
    if isinstance(value, list) and all(
        isinstance(b, int) and not isinstance(b, bool) and 0 <= b <= 255 for b in value
    ):
        return bytes(value)
    raise _MismatchError(path, f"expected base64 text or a list of 0-255 integers, got {_show(value)}")
