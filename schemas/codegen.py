"""Shared machinery of the converter generators: source lines, fresh names, constants, compile.

A generator writes Python source for one message type; :meth:`Source.compile` turns it into a
function once, the way rosbags builds its own (de)serialisers. Constants (``struct.Struct``
methods, lookup tables, error context) are passed in the function's globals, never formatted
into the text, so no input data ever becomes code.
"""

from __future__ import annotations

import struct
from abc import ABC, abstractmethod
from collections.abc import Callable, Hashable
from typing import Any

from fleetlink.schemas import wire
from fleetlink.schemas.layout import Array, Node, Prim, Record, Text

# Names every generated function may use.
BASE_NAMESPACE: dict[str, Any] = {
    "_WireError": wire.WireError,
    "_WireRange": wire.WireRange,
    "_zz": wire.zz,
    "_count": wire.count,
    "_zz_many": wire.zz_many,
    "_read_long": wire.read_long,
    "_read_bytes": wire.read_bytes,
    "_read_text": wire.read_text,
    "_read_array_raw": wire.read_array_raw,
    "_read_array_longs": wire.read_array_longs,
    "_read_block": wire.read_block,
    "_pack_ints": wire.pack_ints,
    "_check_utf8": wire.check_utf8,
    "_utf8": wire.utf8,
    "_check_bools": wire.check_bools,
    "_check_uint64": wire.check_uint64,
    "_swap": wire.swap,
    "_truncated": wire.truncated,
    "_offset_of": wire.offset_of,
    "_UNEXPECTED": wire.UNEXPECTED,
    "_unpack_from": struct.unpack_from,
    "_BOOL": (b"\x00", b"\x01"),
    "_ZEROS": tuple(bytes(i) for i in range(16)),
}


# The end of every generated converter: internal signals become errors naming the type.
HANDLERS = [
    "    except _WireError as exc:",
    "        raise _DecodeError(_TYPENAME, exc.offset, exc.reason, buf) from None",
    "    except _WireRange as exc:",
    "        raise _ValueRangeError(",
    "            _TYPENAME, exc.field, exc.value, exc.reason, exc.offset, data=buf",
    "        ) from None",
    "    except _UNEXPECTED as exc:",
    "        raise _DecodeError(_TYPENAME, _offset_of(exc), 'malformed input: ' + str(exc), buf) from None",
]


class Source:
    """Lines of one generated module with fresh local names and registered constants."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.depth = 0
        self.namespace: dict[str, Any] = dict(BASE_NAMESPACE)
        self._counters: dict[str, int] = {}
        self._consts: dict[Hashable, str] = {}

    def line(self, text: str) -> None:
        """Append ``text`` indented to the current depth."""
        self.lines.append("    " * self.depth + text)

    def var(self, prefix: str) -> str:
        """A fresh local variable name."""
        n = self._counters.get(prefix, 0)
        self._counters[prefix] = n + 1
        return f"{prefix}{n}"

    def const(self, prefix: str, key: Hashable, value: object) -> str:
        """The global name bound to ``value`` (one name per ``key``)."""
        name = self._consts.get(key)
        if name is None:
            name = self.var(f"_{prefix}")
            self._consts[key] = name
            self.namespace[name] = value
        return name

    def text(self) -> str:
        """The generated module's source text."""
        return "\n".join(self.lines) + "\n"

    def compile(self, funcname: str, filename: str) -> Callable[..., Any]:
        """Execute the source with the registered constants as globals; returns the function ``funcname``.

        ``filename`` is what tracebacks through the generated code name.
        """
        code = compile(self.text(), filename, "exec")
        exec(code, self.namespace)  # noqa: S102 (source built from a type definition, constants passed as globals)
        func: Callable[..., Any] = self.namespace[funcname]
        return func


def round_up(value: int, alignment: int) -> int:
    """``value`` rounded up to a multiple of ``alignment`` (a power of two)."""
    return (value + alignment - 1) & -alignment


def known_alignment(base_alignment: int, offset: int) -> int:
    """Alignment of ``base + offset`` when ``base`` is ``base_alignment``-aligned (max 8)."""
    low = offset & -offset if offset else 8
    return min(base_alignment, low, 8)


class NodeWalker(ABC):
    """A generator's walk over a type's layout: one method per kind of node, in wire order."""

    def node(self, node: Node) -> None:
        """Dispatch ``node`` to the method for its kind; a record's fields are walked in order."""
        if isinstance(node, Prim):
            self.prim(node)
        elif isinstance(node, Text):
            self.text(node)
        elif isinstance(node, Record):
            for field in node.fields:
                self.node(field)
        elif isinstance(node.elem, Prim):
            if node.fixed:
                self.prim_array(node.elem.kind, node.size, node.path)
            else:
                self.prim_sequence(node.elem.kind, node.size, node.path)
        else:
            self.repeated(node)

    @abstractmethod
    def prim(self, node: Prim) -> None:
        """Handle one primitive field."""

    @abstractmethod
    def text(self, node: Text) -> None:
        """Handle one string field."""

    @abstractmethod
    def prim_array(self, kind: str, size: int, path: str) -> None:
        """Handle a fixed-size array of ``size`` primitives of ``kind``."""

    @abstractmethod
    def prim_sequence(self, kind: str, bound: int, path: str) -> None:
        """Handle a sequence of primitives of ``kind``, at most ``bound`` long (0: unbounded)."""

    @abstractmethod
    def repeated(self, node: Array) -> None:
        """Handle an array or sequence whose elements are strings, records or arrays."""
