"""Generate an Avro binary -> CDR converter specialised for one message type.

The output is exactly what rosbags / Fast-CDR write: little-endian, encapsulation ``00 01 00 00``,
padding bytes zero, alignment relative to the first byte after the header. Integers are read as
varints and range-checked for their ROS type, then packed with one ``struct`` call per run;
``float``/``double`` runs are copied as slices. Primitive arrays expect the canonical encoding
(one block, as fastavro and the Java library write it) and fall back to a general block reader
for any other valid encoding.
"""

from __future__ import annotations

from collections.abc import Callable
from struct import Struct
from typing import Any

from fleetlink.schemas.codegen import HANDLERS, NodeWalker, Source, known_alignment
from fleetlink.schemas.layout import (
    BYTES_KINDS,
    FLOATS,
    FORMATS,
    RANGES,
    SIZES,
    Array,
    Prim,
    Record,
    Text,
)
from fleetlink.schemas.wire import count, zz

Piece = tuple[str, Any]
_NO_PIECE: Piece = ("", ("", 0, 0))


class AvroToCdr(NodeWalker):
    """Writes ``def convert(buf) -> bytes`` (Avro body in, CDR with header out) for one type."""

    def __init__(self, root: Record) -> None:
        self.root = root
        self.src = Source()
        # input (Avro) position: abase + aoff, abase None = constant 0
        self.abase: str | None = None
        self.aoff = 0
        self.table: list[tuple[int, int, str]] = []
        self.checks: list[str] = []
        # output (CDR) position relative to the end of the header: qbase + qoff
        self.qbase: str | None = None
        self.qoff = 0
        self.qalign = 8
        self.pad = 0
        self.pieces: list[Piece] = [("c", b"\x00\x01\x00\x00")]

    # --- input -----------------------------------------------------------------------------
    def ain(self, off: int) -> str:
        """The source expression of the input position ``off`` bytes after the current input base."""
        if self.abase is None:
            return str(off)
        return f"{self.abase} + {off}" if off else self.abase

    def set_input(self, name: str) -> None:
        """Make the variable ``name`` the input base, with the input offset back at 0."""
        self.abase, self.aoff = name, 0

    def flush_input(self) -> None:
        """Emit one bounds check over the input taken since the last flush, then the checks queued on it."""
        if not self.table:
            return
        extent = max(end for _, end, _ in self.table)
        table = self.src.const("T", ("table", self.src.var("t")), tuple(self.table))
        self.src.line(f"if {self.ain(extent)} > n: _truncated(buf, {self.ain(0)}, {table})")
        for check in self.checks:
            self.src.line(check)
        self.table, self.checks = [], []

    def take_raw(self, nbytes: int, path: str) -> tuple[str | None, int, int]:
        """Take ``nbytes`` of input (bounds-checked at the next flush); returns (base, start, end)."""
        start = self.aoff
        self.table.append((start, start + nbytes, path))
        self.aoff += nbytes
        return self.abase, start, start + nbytes

    def read_long(self) -> tuple[str, str]:
        """Emit a varint read; returns (value name, input offset expression it was read at)."""
        self.flush_input()
        value, pos = self.src.var("v"), self.src.var("a")
        at = self.ain(self.aoff)
        self.src.line(f"{value}, {pos} = _read_long(buf, {at})")
        self.set_input(pos)
        return value, at

    # --- output ----------------------------------------------------------------------------
    def qat(self, off: int) -> str:
        """The source expression of the output position ``off`` bytes after the current output base."""
        if self.qbase is None:
            return str(off)
        return f"{self.qbase} + {off}" if off else self.qbase

    def set_output(self, name: str, alignment: int) -> None:
        """Make the variable ``name`` the output base, known ``alignment``-aligned; offset and padding 0."""
        self.qbase, self.qoff, self.qalign, self.pad = name, 0, alignment, 0

    def out_align(self, a: int) -> None:
        """Align the output to ``a`` bytes: pending zeros when the base allows, else padding at run time."""
        if a <= self.qalign:
            pad = (-self.qoff) % a
            self.pad += pad
            self.qoff += pad
            return
        zeros, name = self.src.var("z"), self.src.var("q")
        here = self.qat(self.qoff)
        self.src.line(f"{zeros} = -({here}) & {a - 1}")
        self.expr(f"_ZEROS[{zeros}]")
        self.src.line(f"{name} = {here} + {zeros}")
        self.set_output(name, a)

    def _take_pad(self) -> None:
        if self.pad:
            pad, self.pad = self.pad, 0
            self.const(bytes(pad))

    def const(self, data: bytes) -> None:
        """Append constant output bytes after any pending padding (merged with a preceding constant)."""
        self._take_pad()
        if self.pieces and self.pieces[-1][0] == "c":
            self.pieces[-1] = ("c", self.pieces[-1][1] + data)
        else:
            self.pieces.append(("c", data))

    def expr(self, text: str) -> None:
        """Append the value of the source expression ``text`` (bytes) after any pending padding."""
        self._take_pad()
        self.pieces.append(("e", text))

    def pack(self, char: str, value: str) -> None:
        """Append one primitive (already aligned) to the current packed run."""
        pad, self.pad = self.pad, 0
        last = self.pieces[-1] if self.pieces else _NO_PIECE
        if last[0] == "p":
            fmt, values = last[1]
            self.pieces[-1] = ("p", (fmt + "x" * pad + char, [*values, value]))
        else:
            self.pieces.append(("p", ("x" * pad + char, [value])))
        self.qoff += Struct(char).size

    def raw(self, source: tuple[str | None, int, int]) -> None:
        """Copy an input span from :meth:`take_raw` to the output unchanged (merged with one it continues)."""
        base, start, end = source
        last = self.pieces[-1] if self.pieces else _NO_PIECE
        if not self.pad and last[0] == "r" and last[1][0] == base and last[1][2] == start:
            self.pieces[-1] = ("r", (base, last[1][1], end))
        else:
            self._take_pad()
            self.pieces.append(("r", source))
        self.qoff += end - start

    def render(self, piece: Piece) -> str:
        """The source expression of one output piece: constant, expression, packed run, or input slice."""
        kind, value = piece
        if kind == "c":
            return repr(value)
        if kind == "e":
            return str(value)
        if kind == "p":
            fmt, values = value
            pack = self.src.const("P", ("pack", fmt), Struct("<" + fmt).pack)
            return f"{pack}({', '.join(values)})"
        base, start, end = value
        saved = self.abase
        self.abase = base
        text = f"buf[{self.ain(start)}:{self.ain(end)}]"
        self.abase = saved
        return text

    def flush_pieces(self) -> None:
        """Emit the pending output pieces (and padding) as one extension of the output list ``o``."""
        self._take_pad()
        if self.pieces:
            self.src.line(f"o += ({', '.join(self.render(p) for p in self.pieces)},)")
            self.pieces = []

    def advance_output(self, length_expr: str, alignment: int) -> None:
        """Move the output base past ``length_expr`` bytes; the new base is ``alignment``-aligned."""
        name = self.src.var("q")
        self.src.line(f"{name} = {self.qat(self.qoff)} + {length_expr}")
        self.set_output(name, alignment)

    # --- nodes -----------------------------------------------------------------------------
    def range_check(self, kind: str, value: str, path: str, at: str) -> None:
        """Emit the check that ``value`` fits the ROS integer ``kind`` (``_WireRange`` at offset ``at``)."""
        lo, hi = RANGES[kind]
        self.src.line(f"if not {lo} <= {value} <= {hi}:")
        self.src.line(f"    raise _WireRange({path!r}, {value}, 'outside [{lo}, {hi}]', {at})")

    def prim(self, node: Prim) -> None:
        """Convert one scalar: floats copied, bools checked and copied, integers range-checked and packed."""
        kind, size = node.kind, SIZES[node.kind]
        if kind in FLOATS:
            self.out_align(size)
            self.raw(self.take_raw(size, node.path))
        elif kind == "bool":
            at = self.ain(self.aoff)
            self.checks.append(f"if buf[{at}] > 1: raise _WireError({at}, 'invalid boolean byte')")
            self.out_align(1)
            self.raw(self.take_raw(1, node.path))
        else:
            value, at = self.read_long()
            self.range_check(kind, value, node.path, at)
            self.out_align(size)
            self.pack(FORMATS[kind], value)

    def text(self, node: Text) -> None:
        """Convert a string: read it (UTF-8 and bound checked) and write CDR length, bytes and NUL."""
        self.flush_input()
        raw, pos = self.src.var("s"), self.src.var("a")
        self.src.line(f"{raw}, {pos} = _read_text(buf, {self.ain(self.aoff)}, {node.bound})")
        self.set_input(pos)
        self.out_align(4)
        self.pack("I", f"len({raw}) + 1")
        self.expr(raw)
        self.const(b"\x00")
        self.advance_output(f"len({raw}) + 1", 1)

    def framed(self, prefix: bytes, nbytes: int, itemsize: int, path: str) -> str:
        """A fixed-length bytes (itemsize 0) or raw-item array, canonical encoding first."""
        src = self.src
        at = self.ain(self.aoff)
        tail = 0 if itemsize == 0 else 1
        self.table.append((self.aoff, self.aoff + len(prefix) + nbytes + tail, path))
        self.flush_input()
        data, pos = src.var("r"), src.var("a")
        body = self.aoff + len(prefix)
        probe = f"buf[{at}:{self.ain(body)}] == {prefix!r}"
        if tail:
            probe += f" and not buf[{self.ain(body + nbytes)}]"
        src.line(f"if {probe}:")
        src.line(f"    {data} = buf[{self.ain(body)}:{self.ain(body + nbytes)}]")
        src.line(f"    {pos} = {self.ain(body + nbytes + tail)}")
        src.line("else:")
        if itemsize == 0:
            src.line(f"    {data}, {pos} = _read_bytes(buf, {at})")
        else:
            src.line(f"    _, {data}, {pos} = _read_array_raw(buf, {at}, {itemsize})")
        src.line(
            f"    if len({data}) != {nbytes}: raise _WireError({at}, "
            f"'{path} holds ' + str(len({data})) + ' bytes, expected {nbytes}')"
        )
        self.set_input(pos)
        return data

    def prim_array(self, kind: str, size: int, path: str) -> None:
        """Convert a fixed array of primitives; any count but ``size`` items raises ``_WireError``."""
        itemsize = SIZES[kind]
        if kind in BYTES_KINDS:
            data = self.framed(zz(size), size, 0, path)
        elif kind in FLOATS or kind == "bool":
            at = self.ain(self.aoff)
            data = self.framed(count(size), size * itemsize, itemsize, path)
            if kind == "bool":
                self.src.line(f"_check_bools({data}, {at})")
        else:
            self.flush_input()
            values, pos = self.src.var("l"), self.src.var("a")
            at = self.ain(self.aoff)
            self.src.line(f"{values}, {pos} = _read_array_longs(buf, {at})")
            self.src.line(
                f"if len({values}) != {size}: raise _WireError({at}, "
                f"'{path} has ' + str(len({values})) + ' items, expected {size}')"
            )
            self.set_input(pos)
            data = f"_pack_ints({FORMATS[kind]!r}, {values}, {RANGES[kind]!r}, {path!r}, {at})"
        self.out_align(itemsize)
        self.expr(data)
        self.qoff += size * itemsize

    def bound_check(self, length: str, bound: int, path: str, at: str) -> None:
        """Emit the check that ``length`` stays within ``bound`` (nothing for an unbounded sequence)."""
        if bound:
            self.src.line(
                f"if {length} > {bound}: raise _WireError({at}, "
                f"'{path} has ' + str({length}) + ' items, more than its bound {bound}')"
            )

    def prim_sequence(self, kind: str, bound: int, path: str) -> None:
        """Convert a sequence of primitives: read the items, check the bound, write count, padding, items."""
        src, itemsize = self.src, SIZES[kind]
        self.flush_input()
        at, pos = self.ain(self.aoff), src.var("a")
        length = src.var("c")
        if kind in BYTES_KINDS:
            data = src.var("r")
            src.line(f"{data}, {pos} = _read_bytes(buf, {at})")
            src.line(f"{length} = len({data})")
        elif kind in FLOATS or kind == "bool":
            data = src.var("r")
            src.line(f"{length}, {data}, {pos} = _read_array_raw(buf, {at}, {itemsize})")
            if kind == "bool":
                src.line(f"_check_bools({data}, {at})")
        else:
            values = src.var("l")
            src.line(f"{values}, {pos} = _read_array_longs(buf, {at})")
            src.line(f"{length} = len({values})")
            data = f"_pack_ints({FORMATS[kind]!r}, {values}, {RANGES[kind]!r}, {path!r}, {at})"
        self.set_input(pos)
        self.bound_check(length, bound, path, at)
        self.out_align(4)
        self.pack("I", length)
        if itemsize > known_alignment(self.qalign, self.qoff):
            zeros = src.var("z")
            src.line(f"{zeros} = -({self.qat(self.qoff)}) & {itemsize - 1} if {length} else 0")
            self.expr(f"_ZEROS[{zeros}]")
            self.expr(data)
            self.advance_output(f"{zeros} + {length} * {itemsize}", min(itemsize, 4))
        else:
            self.expr(data)
            size_expr = length if itemsize == 1 else f"{length} * {itemsize}"
            self.advance_output(size_expr, min(itemsize, 4))

    def repeated(self, node: Array) -> None:
        """Convert an array or sequence of strings, records or arrays with a loop over the Avro blocks.

        A fixed array must have exactly ``size`` items; a sequence's CDR count is filled in once the
        blocks are read.
        """
        src = self.src
        self.flush_input()
        slot = None
        if not node.fixed:
            self.out_align(4)
            self.flush_pieces()
            slot = src.var("i")
            src.line(f"{slot} = len(o)")
            src.line("o.append(b'')")
            self.qoff += 4
        else:
            self.flush_pieces()
        total, block, pos, qpos = src.var("c"), src.var("b"), src.var("a"), src.var("q")
        at = self.ain(self.aoff)
        src.line(f"{total} = 0")
        src.line(f"{block}, {pos} = _read_block(buf, {at})")
        src.line(f"{qpos} = {self.qat(self.qoff)}")
        src.line(f"while {block}:")
        src.line(f"    {total} += {block}")
        src.line(f"    for _ in range({block}):")
        src.depth += 2
        self.set_input(pos)
        self.set_output(qpos, 1)
        self.node(node.elem)
        self.flush_input()
        self.flush_pieces()
        if self.abase != pos or self.aoff:
            src.line(f"{pos} = {self.ain(self.aoff)}")
        if self.qbase != qpos or self.qoff:
            src.line(f"{qpos} = {self.qat(self.qoff)}")
        src.depth -= 1
        src.line(f"{block}, {pos} = _read_block(buf, {pos})")
        src.depth -= 1
        if node.fixed:
            src.line(
                f"if {total} != {node.size}: raise _WireError({at}, "
                f"'{node.path} has ' + str({total}) + ' items, expected {node.size}')"
            )
        else:
            self.bound_check(total, node.size, node.path, at)
            src.line(f"o[{slot}] = _U32({total})")
        self.set_input(pos)
        self.set_output(qpos, 1)

    # --- the function ----------------------------------------------------------------------
    def generate(self) -> str:
        """Write the whole ``convert`` function; returns the module source."""
        src = self.src
        src.namespace["_U32"] = Struct("<I").pack
        src.line("def convert(buf):")
        src.line("    if buf.__class__ is not bytes:")
        src.line("        buf = bytes(buf)")
        src.line("    n = len(buf)")
        src.line("    o = []")
        src.line("    try:")
        src.depth = 2
        self.node(self.root)
        self.flush_input()
        end = self.ain(self.aoff)
        src.line(f"if {end} != n: raise _WireError({end}, 'input continues after the end of the record')")
        self.flush_pieces()
        src.line("return b''.join(o)")
        src.depth = 1
        src.lines.extend(HANDLERS)
        return src.text()

    def compile(self, namespace: dict[str, Any]) -> Callable[[bytes], bytes]:
        """Generate and compile ``convert``, with ``namespace`` (error classes, type name) in its globals."""
        self.generate()
        self.src.namespace.update(namespace)
        return self.src.compile("convert", f"<avro->cdr {self.root.typename}>")
