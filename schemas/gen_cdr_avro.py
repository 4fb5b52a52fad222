"""Generate a CDR -> Avro binary converter specialised for one message type.

The generated function walks the CDR buffer once. Offsets that are known when the code is
generated stay constants relative to the last variable-length item (a string or a sequence), so
a run of fixed-size fields is read with one ``struct`` call. Little-endian ``float32``/``float64``
are byte-identical in CDR and Avro, so runs of them (and whole primitive arrays: count + raw
items + 0) are copied as slices; integers become zigzag varints; strings become length + bytes.
Alignment is relative to byte 4 (after the encapsulation header). Every read is bounds-checked
before it happens, so bad input ends in ``WireError``/``WireRange`` with an offset, which the
wrapper turns into ``DecodeError``/``ValueRangeError`` naming the type.
"""

from __future__ import annotations

from collections.abc import Callable
from struct import Struct
from typing import Any

from fleetlink.schemas.codegen import HANDLERS, NodeWalker, Source, known_alignment, round_up
from fleetlink.schemas.layout import (
    BYTES_KINDS,
    FLOATS,
    FORMATS,
    SIZES,
    Array,
    Prim,
    Record,
    Text,
    min_cdr_size,
)
from fleetlink.schemas.wire import count, zz

Piece = tuple[str, Any]
_UINT64_MAX_LONG = 0x7FFF_FFFF_FFFF_FFFF


class CdrToAvro(NodeWalker):
    """Writes ``def convert(buf) -> bytes`` for one type and byte order."""

    def __init__(self, root: Record, *, little_endian: bool) -> None:
        self.root = root
        self.le = little_endian
        self.order = "<" if little_endian else ">"
        self.src = Source()
        self.base: str | None = None  # None: the base is the constant 4
        self.off = 0
        self.align = 8
        self.reads: list[tuple[int, str, str]] = []
        self.array_reads: list[tuple[int, str, str]] = []
        self.checks: list[str] = []
        self.table: list[tuple[int, int, str]] = []
        self.pieces: list[Piece] = []
        self.uses_list = False
        self.uses_view = False

    # --- positions -------------------------------------------------------------------------
    def at(self, off: int) -> str:
        """The source expression of the input position ``off`` bytes after the current base."""
        if self.base is None:
            return str(4 + off)
        return f"{self.base} + {off}" if off else self.base

    def set_base(self, name: str, alignment: int) -> None:
        """Make the variable ``name`` the base, known to be ``alignment``-aligned; offsets restart at 0."""
        self.base, self.off, self.align = name, 0, alignment

    def align_to(self, a: int) -> None:
        """Align the offset to ``a`` bytes: a constant step when the base allows, else a new base.

        CDR alignment counts from byte 4, the first after the encapsulation header.
        """
        if a <= self.align:
            self.off = round_up(self.off, a)
            return
        self.flush_segment()
        name = self.src.var("p")
        here = self.at(self.off)
        if a <= 4:
            self.src.line(f"{name} = ({here} + {a - 1}) & {-a}")
        else:
            self.src.line(f"{name} = (({here} + {a - 5}) & {-a}) + 4")
        self.set_base(name, a)

    # --- the current run of fixed offsets --------------------------------------------------
    def read(self, kind: str, path: str) -> str:
        """Queue a read of one ``kind`` primitive at the current offset; returns the variable it goes into."""
        name = self.src.var("v")
        size = SIZES[kind]
        self.reads.append((self.off, FORMATS[kind], name))
        self.table.append((self.off, self.off + size, path))
        self.off += size
        return name

    def raw(self, nbytes: int, itemsize: int, path: str) -> None:
        """Copy ``nbytes`` of input to the output unchanged (swapped per ``itemsize`` item when big-endian).

        A copy that continues the previous one from the same base is merged into it.
        """
        start = self.off
        self.table.append((start, start + nbytes, path))
        self.off += nbytes
        last = self.pieces[-1] if self.pieces else None
        if (
            last is not None
            and last[0] == "r"
            and last[1][0] == self.base
            and last[1][2] == start
            and (self.le or last[1][3] == itemsize)
        ):
            self.pieces[-1] = ("r", (self.base, last[1][1], start + nbytes, itemsize))
        else:
            self.pieces.append(("r", (self.base, start, start + nbytes, itemsize)))

    def flush_segment(self) -> None:
        """Emit the current run: one bounds check over it, one ``struct`` unpack, array reads, checks."""
        if not self.table:
            return
        src = self.src
        extent = max(end for _, end, _ in self.table)
        table = src.const("T", ("table", src.var("t")), tuple(self.table))
        src.line(f"if {self.at(extent)} > n: _truncated(buf, {self.at(0)}, {table})")
        if self.reads:
            fmt, cur = "", self.reads[0][0]
            for off, char, _ in self.reads:
                fmt += "x" * (off - cur) + char
                cur = off + Struct(char).size
            unpack = src.const("S", ("struct", self.order + fmt), Struct(self.order + fmt).unpack_from)
            names = ", ".join(name for _, _, name in self.reads)
            src.line(f"{names}, = {unpack}(buf, {self.at(self.reads[0][0])})")
        for off, fmt, name in self.array_reads:
            unpack = src.const("S", ("struct", self.order + fmt), Struct(self.order + fmt).unpack_from)
            src.line(f"{name} = {unpack}(buf, {self.at(off)})")
        for check in self.checks:
            src.line(check)
        self.reads, self.array_reads, self.checks, self.table = [], [], [], []

    # --- output ----------------------------------------------------------------------------
    def const(self, data: bytes) -> None:
        """Append constant output bytes (merged with a preceding constant)."""
        if self.pieces and self.pieces[-1][0] == "c":
            self.pieces[-1] = ("c", self.pieces[-1][1] + data)
        elif data:
            self.pieces.append(("c", data))

    def expr(self, text: str) -> None:
        """Append the value of the source expression ``text`` (bytes) to the output."""
        self.pieces.append(("e", text))

    def render(self, piece: Piece) -> str:
        """The source expression of one output piece: a constant, an expression, or an input slice."""
        kind, value = piece
        if kind == "c":
            return repr(value)
        if kind == "e":
            return str(value)
        base, start, end, itemsize = value
        saved = self.base
        self.base = base
        lo, hi = self.at(start), self.at(end)
        self.base = saved
        if self.le or itemsize == 1:
            return f"buf[{lo}:{hi}]"
        return f"_swap(buf, {lo}, {end - start}, {itemsize})"

    def flush_pieces(self) -> None:
        """Emit the pending output pieces as one extension of the output list ``o``."""
        if self.pieces:
            self.uses_list = True
            items = ", ".join(self.render(p) for p in self.pieces)
            self.src.line(f"o += ({items},)")
            self.pieces = []

    # --- nodes -----------------------------------------------------------------------------
    def prim(self, node: Prim) -> None:
        """Convert one scalar: floats copied, bools checked, integers zigzag-encoded (uint64 <= 2**63-1)."""
        kind, size = node.kind, SIZES[node.kind]
        self.align_to(size)
        if kind in FLOATS:
            self.raw(size, size, node.path)
            return
        at = self.at(self.off)
        name = self.read(kind, node.path)
        if kind == "bool":
            self.checks.append(f"if {name} > 1: raise _WireError({at}, 'invalid bool byte ' + str({name}))")
            self.expr(f"_BOOL[{name}]")
            return
        if kind == "uint64":
            self.checks.append(
                f"if {name} > {_UINT64_MAX_LONG}: raise _WireRange({node.path!r}, {name}, "
                f"'uint64 above 2**63-1 does not fit an Avro long', {at})"
            )
        self.expr(f"_zz({name})")

    def text_span(self, node: Text) -> tuple[str, str, str]:
        """Emit the reading and checks of a CDR string's length, terminator and bound; returns
        the expressions ``(start, end, length)`` of its bytes (``buf[start:end - 1]`` without the
        NUL). The caller emits the text itself, then ``set_base(end, 1)``."""
        src = self.src
        self.align_to(4)
        lpos = self.off
        length = self.read("uint32", node.path)
        self.flush_segment()
        start, end = self.at(lpos + 4), src.var("e")
        src.line(f"{end} = {start} + {length}")
        src.line(
            f"if {length} == 0 or {end} > n: raise _WireError({self.at(lpos)}, "
            f"'string length ' + str({length}) + ' does not fit in ' + str(n) + ' bytes')"
        )
        src.line(f"if buf[{end} - 1]: raise _WireError({end} - 1, 'string is not NUL-terminated')")
        if node.bound:
            src.line(
                f"if {length} > {node.bound + 1}: raise _WireError({self.at(lpos)}, "
                f"'string longer than its bound {node.bound}')"
            )
        return start, end, length

    def text(self, node: Text) -> None:
        """Convert a string: check its length, NUL, bound and UTF-8; write Avro length and bytes."""
        start, end, length = self.text_span(node)
        text = self.src.var("s")
        self.src.line(f"{text} = buf[{start}:{end} - 1]")
        self.src.line(f"if not {text}.isascii(): _check_utf8({text}, {start})")
        self.expr(f"_zz({length} - 1)")
        self.expr(text)
        self.set_base(end, 1)

    def prim_array(self, kind: str, size: int, path: str) -> None:
        """Convert a fixed array of primitives: byte kinds as Avro bytes, others as one Avro array block."""
        itemsize = SIZES[kind]
        self.align_to(itemsize)
        start = self.off
        if kind in BYTES_KINDS:
            self.const(zz(size))
            self.raw(size, 1, path)
        elif kind in FLOATS or kind == "bool":
            self.const(count(size))
            self.raw(size * itemsize, itemsize, path)
            self.const(b"\x00")
            if kind == "bool":
                self.checks.append(
                    f"_check_bools(buf[{self.at(start)}:{self.at(start + size)}], {self.at(start)})"
                )
        else:
            name = self.src.var("a")
            self.array_reads.append((start, f"{size}{FORMATS[kind]}", name))
            self.table.append((start, start + size * itemsize, path))
            self.off += size * itemsize
            self.const(count(size))
            self.expr(f"_zz_many({name})")
            self.const(b"\x00")
            if kind == "uint64":
                self.checks.append(f"_check_uint64({name}, {path!r}, {self.at(start)})")

    def sequence_count(self, bound: int, path: str) -> tuple[str, int]:
        """Emit the read of a sequence's count and its bound check; returns the count variable and offset."""
        self.align_to(4)
        cpos = self.off
        name = self.read("uint32", path)
        self.flush_segment()
        if bound:
            self.src.line(
                f"if {name} > {bound}: raise _WireError({self.at(cpos)}, "
                f"'sequence of ' + str({name}) + ' items exceeds its bound {bound}')"
            )
        return name, cpos

    def sequence_span(self, kind: str, bound: int, path: str) -> tuple[str, str, str]:
        """Emit the reading of a sequence's count, the alignment of its items and the check that
        they fit; returns the expressions ``(count, start, end)``."""
        src, itemsize = self.src, SIZES[kind]
        n_items, cpos = self.sequence_count(bound, path)
        after = self.at(cpos + 4)
        start, end = src.var("d"), src.var("e")
        if itemsize <= known_alignment(self.align, cpos + 4):
            src.line(f"{start} = {after}")
        else:
            src.line(f"{start} = (({after} + 3) & -8) + 4 if {n_items} else {after}")
        src.line(f"{end} = {start} + {n_items}" + (f" * {itemsize}" if itemsize > 1 else ""))
        src.line(
            f"if {end} > n: raise _WireError({self.at(cpos)}, 'sequence of ' + str({n_items}) + "
            f"' items does not fit in ' + str(n) + ' bytes')"
        )
        return n_items, start, end

    def prim_sequence(self, kind: str, bound: int, path: str) -> None:
        """Convert a sequence of primitives: byte kinds as Avro bytes, others as one Avro array block."""
        src, itemsize = self.src, SIZES[kind]
        n_items, start, end = self.sequence_span(kind, bound, path)
        self.uses_view = True
        data = (
            f"mv[{start}:{end}]"
            if self.le or itemsize == 1
            else f"_swap(buf, {start}, {end} - {start}, {itemsize})"
        )
        if kind in BYTES_KINDS:
            self.expr(f"_zz({n_items})")
            self.expr(data)
        elif kind in FLOATS or kind == "bool":
            if kind == "bool":
                src.line(f"_check_bools(buf[{start}:{end}], {start})")
            self.expr(f"_count({n_items})")
            self.expr(data)
            self.const(b"\x00")
        else:
            values = src.var("a")
            src.line(f"{values} = _unpack_from(f'{self.order}{{{n_items}}}{FORMATS[kind]}', buf, {start})")
            if kind == "uint64":
                src.line(f"_check_uint64({values}, {path!r}, {start})")
            self.expr(f"_count({n_items})")
            self.expr(f"_zz_many({values})")
            self.const(b"\x00")
        self.set_base(end, min(itemsize, 4))

    def repeated(self, node: Array) -> None:
        """Convert an array or sequence of strings, records or arrays with a generated loop over its items."""
        src = self.src
        elem = node.elem
        if node.fixed:
            n_items = str(node.size)
            self.const(count(node.size))
        else:
            n_items, cpos = self.sequence_count(node.size, node.path)
            smallest = max(min_cdr_size(elem), 1)
            src.line(
                f"if {n_items} * {smallest} > n - ({self.at(cpos + 4)}): raise _WireError({self.at(cpos)}, "
                f"'sequence count ' + str({n_items}) + ' cannot fit in ' + str(n) + ' bytes')"
            )
            self.expr(f"_count({n_items})")
        self.flush_segment()
        self.flush_pieces()
        loop = src.var("p")
        src.line(f"{loop} = {self.at(self.off)}")
        src.line(f"for _ in range({n_items}):")
        src.depth += 1
        self.set_base(loop, 1)
        self.node(elem)
        self.flush_segment()
        self.flush_pieces()
        if self.base != loop or self.off:
            src.line(f"{loop} = {self.at(self.off)}")
        src.depth -= 1
        self.set_base(loop, 1)
        self.const(b"\x00")

    # --- the function ----------------------------------------------------------------------
    def generate(self) -> str:
        """Write the whole ``convert`` function; returns the module source."""
        src = self.src
        src.line("def convert(buf):")
        src.depth = 1
        src.line("if buf.__class__ is not bytes:")
        src.line("    buf = bytes(buf)")
        src.line("n = len(buf)")
        head = "if n < 4 or buf[0] or buf[1] != 1:" if self.le else "if n < 4 or buf[0] or buf[1]:"
        src.line(head)
        src.line("    return _other_encapsulation(buf)")
        prologue = len(src.lines)
        src.line("try:")
        src.depth = 2
        self.node(self.root)
        self.flush_segment()
        end = self.at(self.off)
        src.line(
            f"if n - ({end}) > 3: raise _WireError({end}, "
            f"str(n - ({end})) + ' bytes after the end of the message')"
        )
        if self.uses_list:
            self.flush_pieces()
            src.line("return b''.join(o)")
        else:
            items = ", ".join(self.render(p) for p in self.pieces)
            src.line(f"return b''.join(({items},))" if self.pieces else "return b''")
        src.depth = 1
        src.lines.extend(HANDLERS)
        extra = []
        if self.uses_view:
            extra.append("    mv = memoryview(buf)")
        if self.uses_list:
            extra.append("    o = []")
        src.lines[prologue:prologue] = extra
        return src.text()

    def compile(self, namespace: dict[str, Any]) -> Callable[[bytes], bytes]:
        """Generate and compile ``convert``, with ``namespace`` (error classes, type name) in its globals."""
        self.generate()
        self.src.namespace.update(namespace)
        return self.src.compile("convert", f"<cdr->avro {self.root.typename}>")
