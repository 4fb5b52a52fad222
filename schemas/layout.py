"""A ROS message type as a tree of wire-level nodes, the input of the code generators.

Nested types are expanded in place (each node knows its field path for error messages), so a
generator can emit one flat function per top-level type.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from rosbags.interfaces import Nodetype

from fleetlink.schemas.errors import TypeDefinitionError
from fleetlink.schemas.typestore import fields_of

if TYPE_CHECKING:
    from rosbags.interfaces.typing import FieldDesc
    from rosbags.typesys.store import Typestore

# CDR size (= alignment) and struct format character of each primitive.
SIZES: dict[str, int] = {
    "bool": 1,
    "byte": 1,
    "char": 1,
    "int8": 1,
    "uint8": 1,
    "int16": 2,
    "uint16": 2,
    "int32": 4,
    "uint32": 4,
    "int64": 8,
    "uint64": 8,
    "float32": 4,
    "float64": 8,
}
FORMATS: dict[str, str] = {
    "bool": "B",
    "byte": "B",
    "char": "B",
    "int8": "b",
    "uint8": "B",
    "int16": "h",
    "uint16": "H",
    "int32": "i",
    "uint32": "I",
    "int64": "q",
    "uint64": "Q",
    "float32": "f",
    "float64": "d",
}
# Inclusive value ranges of the integer kinds (uint64 limited to what an Avro long holds).
RANGES: dict[str, tuple[int, int]] = {
    "bool": (0, 1),
    "byte": (0, 0xFF),
    "char": (0, 0xFF),
    "int8": (-0x80, 0x7F),
    "uint8": (0, 0xFF),
    "int16": (-0x8000, 0x7FFF),
    "uint16": (0, 0xFFFF),
    "int32": (-0x8000_0000, 0x7FFF_FFFF),
    "uint32": (0, 0xFFFF_FFFF),
    "int64": (-0x8000_0000_0000_0000, 0x7FFF_FFFF_FFFF_FFFF),
    "uint64": (0, 0x7FFF_FFFF_FFFF_FFFF),
}
FLOATS = frozenset({"float32", "float64"})
BYTES_KINDS = frozenset({"uint8", "byte", "char"})
_MAX_DEPTH = 64


@dataclass(frozen=True)
class Prim:
    """A primitive scalar (not a string)."""

    kind: str
    path: str


@dataclass(frozen=True)
class Text:
    """A string; ``bound`` 0 means unbounded."""

    bound: int
    path: str


@dataclass(frozen=True)
class Record:
    """A nested message."""

    typename: str
    fields: tuple[Node, ...]
    path: str


@dataclass(frozen=True)
class Array:
    """A fixed array (``fixed``: exactly ``size`` items) or a sequence (``size`` = bound, 0 = none)."""

    elem: Prim | Text | Record
    size: int
    fixed: bool
    path: str


Node = Prim | Text | Record | Array


def build(ts: Typestore, typename: str) -> Record:
    """The node tree of ``typename`` (raises ``UnknownTypeError`` for missing nested types)."""
    return _record(ts, typename, "", None, 0)


def _record(ts: Typestore, typename: str, path: str, parent: str | None, depth: int) -> Record:
    if depth > _MAX_DEPTH:
        raise TypeDefinitionError(typename, path, "types nest too deeply (recursive definition?)")
    nodes = []
    for fname, desc in fields_of(ts, typename, parent):
        fpath = f"{path}.{fname}" if path else fname
        nodes.append(_node(ts, desc, fpath, f"{typename}.{fname}", depth))
    return Record(typename, tuple(nodes), path)


def _node(ts: Typestore, desc: FieldDesc, path: str, where: str, depth: int) -> Node:
    if desc[0] == Nodetype.BASE:
        return _scalar(desc[1][0], desc[1][1], path, where)
    if desc[0] == Nodetype.NAME:
        return _record(ts, desc[1], path, where, depth + 1)
    inner, size = desc[1]
    ipath = f"{path}[]"
    elem: Prim | Text | Record
    if inner[0] == Nodetype.BASE:
        elem = _scalar(inner[1][0], inner[1][1], ipath, where)
    else:
        elem = _record(ts, inner[1], ipath, where, depth + 1)
    return Array(elem, size, desc[0] == Nodetype.ARRAY, path)


def _scalar(kind: str, bound: int, path: str, where: str) -> Prim | Text:
    if kind == "string":
        return Text(bound, path)
    if kind not in SIZES:
        owner, _, field = where.rpartition(".")
        raise TypeDefinitionError(owner, field, f"ROS type {kind!r} is not supported")
    return Prim(kind, path)


def min_cdr_size(node: Node) -> int:
    """A lower bound of the CDR size of ``node`` (padding ignored), to reject absurd counts early."""
    if isinstance(node, Prim):
        return SIZES[node.kind]
    if isinstance(node, Text):
        return 5
    if isinstance(node, Record):
        return sum(min_cdr_size(f) for f in node.fields)
    if node.fixed:
        return node.size * min_cdr_size(node.elem)
    return 4


def first_alignment(node: Node) -> int:
    """The alignment CDR applies before ``node`` (that of its first primitive)."""
    if isinstance(node, Prim):
        return SIZES[node.kind]
    if isinstance(node, Text):
        return 4
    if isinstance(node, Record):
        return first_alignment(node.fields[0]) if node.fields else 1
    if node.fixed:
        return first_alignment(node.elem) if node.size else 1
    return 4
