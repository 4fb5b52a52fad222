"""A type layout as a compact program for the native converter (``fleetlink._native``). Pure.

The native data path converts CDR to Avro with the same rules as the generated Python
converter (``gen_cdr_avro``), driven by this description of the type's node tree
(little-endian integers throughout)::

    1 kind:u8                                   a primitive (``KINDS`` order)
    2 bound:u32                                 a string (0: unbounded)
    3 count:u16 node*count                      a nested message
    4 fixed:u8 size:u32 min_size:u32 node       a fixed array (size items) or a sequence (bound)
"""

from __future__ import annotations

import struct

from fleetlink.schemas.layout import Array, Node, Prim, Record, Text, min_cdr_size

KINDS: tuple[str, ...] = (
    "bool",
    "byte",
    "char",
    "int8",
    "uint8",
    "int16",
    "uint16",
    "int32",
    "uint32",
    "int64",
    "uint64",
    "float32",
    "float64",
)
_KIND_CODES = {kind: code for code, kind in enumerate(KINDS)}
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")


def layout_program(root: Record) -> bytes:
    """The program of a message type's node tree (``fleetlink.schemas.layout.build``)."""
    out = bytearray()
    _emit(root, out)
    return bytes(out)


def _emit(node: Node, out: bytearray) -> None:
    if isinstance(node, Prim):
        out += bytes((1, _KIND_CODES[node.kind]))
    elif isinstance(node, Text):
        out += b"\x02" + _U32.pack(node.bound)
    elif isinstance(node, Record):
        if len(node.fields) > 0xFFFF:
            raise ValueError(f"{node.typename} has more fields than a layout program holds")
        out += b"\x03" + _U16.pack(len(node.fields))
        for field in node.fields:
            _emit(field, out)
    else:
        _emit_array(node, out)


def _emit_array(node: Array, out: bytearray) -> None:
    out += (
        b"\x04" + bytes((1 if node.fixed else 0,)) + _U32.pack(node.size) + _U32.pack(min_cdr_size(node.elem))
    )
    _emit(node.elem, out)
