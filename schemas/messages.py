"""ROS messages (rosbags objects) to plain data and back, for people typing and reading them.

``to_data`` gives dicts, lists, numbers, text and bools (``uint8[]`` as a list of numbers), in
field order, as ``ros2 topic echo`` prints them. ``from_data`` builds a message from such data
(parsed YAML, as ``ros2 topic pub`` takes it): fields not given keep their defaults (0, false,
"", empty sequences, arrays of defaults); an unknown field, a wrong type or a wrong array length
is an error naming the field's path. Pure: needs only a type store.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np
from rosbags.interfaces import Nodetype

from fleetlink.schemas.errors import SchemaError
from fleetlink.schemas.typestore import fields_of

if TYPE_CHECKING:
    from rosbags.interfaces.typing import FieldDesc
    from rosbags.typesys.store import Typestore

_INTS = {
    "int8": (-(1 << 7), (1 << 7) - 1),
    "uint8": (0, (1 << 8) - 1),
    "byte": (0, (1 << 8) - 1),
    "char": (0, (1 << 8) - 1),
    "int16": (-(1 << 15), (1 << 15) - 1),
    "uint16": (0, (1 << 16) - 1),
    "int32": (-(1 << 31), (1 << 31) - 1),
    "uint32": (0, (1 << 32) - 1),
    "int64": (-(1 << 63), (1 << 63) - 1),
    "uint64": (0, (1 << 64) - 1),
}
_FLOATS = ("float32", "float64")
_NUMPY = {**{k: k for k in _INTS if k not in ("byte", "char")}, "byte": "uint8", "char": "uint8"}
_NUMPY |= {"float32": "float32", "float64": "float64", "bool": "bool"}


class MessageDataError(SchemaError):
    """Data that does not make a message of the type; names the field."""

    def __init__(self, typename: str, path: str, reason: str) -> None:
        super().__init__(f"{typename}: {path or 'the message'}: {reason}")
        self.typename = typename
        self.path = path


def to_data(message: Any) -> Any:
    """A message (or a value inside one) as plain data."""
    if dataclasses.is_dataclass(message) and not isinstance(message, type):
        return {
            f.name: to_data(getattr(message, f.name))
            for f in dataclasses.fields(message)
            if f.name != "__msgtype__"
        }
    if isinstance(message, np.ndarray):
        return message.tolist()
    if isinstance(message, list | tuple):
        return [to_data(item) for item in message]
    if isinstance(message, np.generic):
        return message.item()
    if isinstance(message, bytes | bytearray):
        return list(message)
    return message


def from_data(ts: Typestore, typename: str, data: Any) -> Any:
    """A message of ``typename`` from plain data (see the module docstring)."""
    return _Builder(ts, typename).message(typename, data, "")


class _Builder:
    def __init__(self, ts: Typestore, root: str) -> None:
        self.ts = ts
        self.root = root

    def fail(self, path: str, reason: str) -> MessageDataError:
        return MessageDataError(self.root, path, reason)

    def message(self, typename: str, data: Any, path: str) -> Any:
        fields = fields_of(self.ts, typename)
        if data is None:
            data = {}
        if not isinstance(data, dict):
            raise self.fail(path, f"expected a mapping of {typename}'s fields, got {data!r}")
        names = [name for name, _ in fields]
        unknown = sorted(set(data) - set(names))
        if unknown:
            raise self.fail(path, f"no field {unknown[0]!r} (fields: {', '.join(names)})")
        values = {}
        for name, desc in fields:
            where = f"{path}.{name}" if path else name
            values[name] = self.value(desc, data.get(name), where, given=name in data)
        return self.ts.types[typename](**values)

    def value(self, field: FieldDesc, data: Any, path: str, *, given: bool) -> Any:
        desc: Any = field  # rosbags' descriptor union does not narrow on its kind
        kind = desc[0]
        if kind == Nodetype.BASE:
            base, bound = desc[1]
            return self.base(base, bound, data, path, given=given)
        if kind == Nodetype.NAME:
            return self.message(desc[1], data if given else None, path)
        inner, size = desc[1]
        if not given or data is None:
            items: list[Any] = [None] * (size if kind == Nodetype.ARRAY else 0)
        elif isinstance(data, list | tuple):
            items = list(data)
        else:
            raise self.fail(path, f"expected a list, got {data!r}")
        if kind == Nodetype.ARRAY and len(items) != size:
            raise self.fail(path, f"expected {size} items, got {len(items)}")
        if kind == Nodetype.SEQUENCE and size and len(items) > size:
            raise self.fail(path, f"at most {size} items, got {len(items)}")
        values = [
            self.value(inner, item, f"{path}[{i}]", given=item is not None) for i, item in enumerate(items)
        ]
        if inner[0] == Nodetype.BASE and inner[1][0] in _NUMPY:
            return np.array(values, dtype=_NUMPY[inner[1][0]])
        return values

    def base(self, base: str, bound: int, data: Any, path: str, *, given: bool) -> Any:
        if base in ("string", "wstring"):
            return self.text(bound, data if given else None, path)
        if base == "bool":
            if given and data is not None and not isinstance(data, bool):
                raise self.fail(path, f"expected true or false, got {data!r}")
            return bool(data) if given else False
        if not given or data is None:
            return 0.0 if base in _FLOATS else 0
        if isinstance(data, bool) or not isinstance(data, int | float):
            raise self.fail(path, f"expected a number ({base}), got {data!r}")
        if base in _FLOATS:
            return float(data)
        if base not in _INTS:
            raise self.fail(path, f"type {base} is not supported here")
        low, high = _INTS[base]
        if not isinstance(data, int) or not low <= data <= high:
            raise self.fail(path, f"expected an integer in {low}..{high} ({base}), got {data!r}")
        return data

    def text(self, bound: int, data: Any, path: str) -> str:
        if data is None:
            return ""
        text = data if isinstance(data, str) else str(data)
        if bound and len(text) > bound:
            raise self.fail(path, f"at most {bound} characters, got {len(text)}")
        return text
