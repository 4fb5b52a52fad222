"""Generate a CDR -> dict decoder specialised for one message type.

The dict has the shape an Avro reader returns for the type's schema (records as dicts in field
order, arrays as lists, ``uint8[]`` as bytes, bools as bools), so stages and templates see the
same values before and after Avro. It shares the CDR walk, alignment and checks of
:class:`~schemas.gen_cdr_avro.CdrToAvro`; only what is produced differs: here every primitive is
unpacked (fixed runs with one ``struct`` call) and the record is one dict expression.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from fleetlink.schemas.codegen import HANDLERS
from fleetlink.schemas.gen_cdr_avro import CdrToAvro
from fleetlink.schemas.layout import (
    BYTES_KINDS,
    FORMATS,
    SIZES,
    Array,
    Node,
    Prim,
    Record,
    Text,
    min_cdr_size,
)

_UINT64_MAX_LONG = 0x7FFF_FFFF_FFFF_FFFF


def _name(node: Node) -> str:
    return node.path.rsplit(".", 1)[-1]


class CdrToDict(CdrToAvro):
    """Writes ``def convert(buf) -> dict`` for one type and byte order."""

    def value(self, node: Node) -> str:
        """Emit the reads of ``node``; returns the source expression of its value.

        Values read in the current run of fixed offsets exist only once :meth:`flush_segment` has emitted it.
        """
        if isinstance(node, Prim):
            return self.prim_value(node)
        if isinstance(node, Text):
            return self.text_value(node)
        if isinstance(node, Record):
            items = [f"{_name(field)!r}: {self.value(field)}" for field in node.fields]
            return "{" + ", ".join(items) + "}"
        if isinstance(node.elem, Prim):
            if node.fixed:
                return self.prim_array_value(node.elem.kind, node.size, node.path)
            return self.prim_sequence_value(node.elem.kind, node.size, node.path)
        return self.repeated_value(node)

    def prim_value(self, node: Prim) -> str:
        """Queue the read of one scalar (bools and uint64 checked); returns its expression."""
        kind = node.kind
        self.align_to(SIZES[kind])
        at = self.at(self.off)
        name = self.read(kind, node.path)
        if kind == "bool":
            self.checks.append(f"if {name} > 1: raise _WireError({at}, 'invalid bool byte ' + str({name}))")
            return f"_BOOLS[{name}]"
        if kind == "uint64":
            self.checks.append(
                f"if {name} > {_UINT64_MAX_LONG}: raise _WireRange({node.path!r}, {name}, "
                f"'uint64 above 2**63-1 does not fit an Avro long', {at})"
            )
        return name

    def text_value(self, node: Text) -> str:
        """Emit the reads and checks of a string; returns the variable holding it decoded."""
        start, end, _length = self.text_span(node)
        text = self.src.var("s")
        self.src.line(f"{text} = _utf8(buf[{start}:{end} - 1], {start})")
        self.set_base(end, 1)
        return text

    def prim_array_value(self, kind: str, size: int, path: str) -> str:
        """Queue a fixed array of primitives: bytes for byte kinds, else a list; returns its expression."""
        itemsize = SIZES[kind]
        self.align_to(itemsize)
        start, end = self.off, self.off + size * itemsize
        span = f"buf[{self.at(start)}:{self.at(end)}]"
        if kind in BYTES_KINDS:
            self.table.append((start, end, path))
            self.off = end
            return span
        if kind == "bool":
            self.table.append((start, end, path))
            self.checks.append(f"_check_bools({span}, {self.at(start)})")
            self.off = end
            return f"list(map(bool, {span}))"
        name = self.src.var("a")
        self.array_reads.append((start, f"{size}{FORMATS[kind]}", name))
        self.table.append((start, end, path))
        if kind == "uint64":
            self.checks.append(f"_check_uint64({name}, {path!r}, {self.at(start)})")
        self.off = end
        return f"list({name})"

    def prim_sequence_value(self, kind: str, bound: int, path: str) -> str:
        """Emit the reads of a primitive sequence (bytes for byte kinds, else a list); returns its value."""
        src, itemsize = self.src, SIZES[kind]
        n_items, start, end = self.sequence_span(kind, bound, path)
        self.set_base(end, min(itemsize, 4))
        if kind in BYTES_KINDS:
            return f"buf[{start}:{end}]"
        if kind == "bool":
            src.line(f"_check_bools(buf[{start}:{end}], {start})")
            return f"list(map(bool, buf[{start}:{end}]))"
        values = src.var("a")
        src.line(f"{values} = _unpack_from(f'{self.order}{{{n_items}}}{FORMATS[kind]}', buf, {start})")
        if kind == "uint64":
            src.line(f"_check_uint64({values}, {path!r}, {start})")
        return f"list({values})"

    def repeated_value(self, node: Array) -> str:
        """Emit a loop collecting the items of an array or sequence of non-primitives; returns the list."""
        src = self.src
        if node.fixed:
            n_items = str(node.size)
        else:
            n_items, cpos = self.sequence_count(node.size, node.path)
            smallest = max(min_cdr_size(node.elem), 1)
            src.line(
                f"if {n_items} * {smallest} > n - ({self.at(cpos + 4)}): raise _WireError({self.at(cpos)}, "
                f"'sequence count ' + str({n_items}) + ' cannot fit in ' + str(n) + ' bytes')"
            )
        self.flush_segment()
        items, loop = src.var("l"), src.var("p")
        src.line(f"{items} = []")
        src.line(f"{loop} = {self.at(self.off)}")
        src.line(f"for _ in range({n_items}):")
        src.depth += 1
        self.set_base(loop, 1)
        item = self.value(node.elem)
        self.flush_segment()
        src.line(f"{items}.append({item})")
        if self.base != loop or self.off:
            src.line(f"{loop} = {self.at(self.off)}")
        src.depth -= 1
        self.set_base(loop, 1)
        return items

    def generate(self) -> str:
        """Write the whole ``convert`` function; returns the module source."""
        src = self.src
        src.namespace["_BOOLS"] = (False, True)
        src.line("def convert(buf):")
        src.depth = 1
        src.line("if buf.__class__ is not bytes:")
        src.line("    buf = bytes(buf)")
        src.line("n = len(buf)")
        src.line(f"if n < 4 or buf[0] or buf[1] != {1 if self.le else 0}:")
        src.line("    return _other_encapsulation(buf)")
        src.line("try:")
        src.depth = 2
        result = self.value(self.root)
        self.flush_segment()
        end = self.at(self.off)
        src.line(
            f"if n - ({end}) > 3: raise _WireError({end}, "
            f"str(n - ({end})) + ' bytes after the end of the message')"
        )
        src.line(f"return {result}")
        src.lines.extend(HANDLERS)
        return src.text()

    def compile_decoder(self, namespace: dict[str, Any]) -> Callable[[bytes], dict[str, Any]]:
        """Generate and compile ``convert``, with ``namespace`` (error classes, type name) in its globals."""
        self.generate()
        self.src.namespace.update(namespace)
        return self.src.compile("convert", f"<cdr->dict {self.root.typename}>")
