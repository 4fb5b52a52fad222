"""What the command and call envelopes and their JSON batches share (pure: bytes in, bytes out).

An envelope is a JSON header and a binary tail behind a three-byte magic::

    magic (3) | version (1) | flags (bit 0: zlib) | rest
    rest = u32 header length (big-endian) | header (JSON, UTF-8) | tail

A batch (status events, call outcomes) is compact JSON, zlib-compressed when that makes a large
one smaller (JSON starts with ``{``, so a reader tells the two apart by the first byte). Every
reader raises :class:`~fleetlink.wire.errors.EnvelopeError` naming what and where it failed.
"""

from __future__ import annotations

import json
import struct
import zlib
from typing import Any

from fleetlink.wire.errors import EnvelopeError

VERSION = 1
FLAG_ZLIB = 0x01
COMPRESS_ABOVE = 160
"""Envelopes and batches larger than this many bytes are sent zlib-compressed (when that makes
them smaller): the WAN is the scarce resource, and the CPU cost is microseconds."""
MAX_ENVELOPE = 8 << 20
HEADER_LEN = struct.Struct(">I")


def pack_envelope(magic: bytes, header: dict[str, Any], tail: bytes, *, compress_above: int) -> bytes:
    """``magic`` | version | flags | header length | ``header`` as JSON | ``tail``."""
    head = json.dumps(header, separators=(",", ":"), ensure_ascii=False).encode()
    rest = HEADER_LEN.pack(len(head)) + head + tail
    flags = 0
    if len(rest) > compress_above:
        packed = zlib.compress(rest, 6)
        if len(packed) < len(rest):
            rest, flags = packed, FLAG_ZLIB
    return magic + bytes((VERSION, flags)) + rest


def unpack_envelope(data: bytes, magic: bytes, what: str) -> tuple[dict[str, Any], bytes]:
    """The JSON header and the tail of an envelope written by :func:`pack_envelope`."""
    if len(data) < 5 or data[:3] != magic:
        raise EnvelopeError(what, f"does not start with {magic!r}", data)
    if data[3] != VERSION:
        raise EnvelopeError(what, f"version {data[3]} is not {VERSION}", data)
    flags, rest = data[4], bytes(data[5:])
    if flags & ~FLAG_ZLIB:
        raise EnvelopeError(what, f"unknown flags 0x{flags:02x}", data)
    if flags & FLAG_ZLIB:
        rest = inflate(rest, what, data)
    if len(rest) < HEADER_LEN.size:
        raise EnvelopeError(what, "truncated before the header length", data)
    (size,) = HEADER_LEN.unpack_from(rest)
    end = HEADER_LEN.size + size
    if end > len(rest):
        raise EnvelopeError(what, f"header of {size} bytes runs past the end", data)
    header = json_object(rest[HEADER_LEN.size : end], f"{what} header", data)
    return header, rest[end:]


def pack_json(obj: dict[str, Any], *, compress_above: int) -> bytes:
    """Compact JSON, zlib-compressed when larger than ``compress_above`` bytes and smaller so."""
    text = json.dumps(obj, separators=(",", ":"), ensure_ascii=False).encode()
    if len(text) > compress_above:
        packed = zlib.compress(text, 6)
        if len(packed) < len(text):
            return packed
    return text


def unpack_json(data: bytes, what: str) -> bytes:
    """The JSON text of ``data`` written by :func:`pack_json` (inflated when it is compressed)."""
    if data[:1] != b"{":
        return inflate(data, what)
    return data


def inflate(packed: bytes, what: str, data: bytes | None = None) -> bytes:
    """``packed`` inflated, refused when it would grow beyond :data:`MAX_ENVELOPE` bytes."""
    data = packed if data is None else data
    try:
        inflater = zlib.decompressobj()
        out = inflater.decompress(packed, MAX_ENVELOPE)
        if inflater.unconsumed_tail:
            raise EnvelopeError(what, f"inflates beyond {MAX_ENVELOPE} bytes", data)
    except zlib.error as exc:
        raise EnvelopeError(what, f"bad zlib data: {exc}", data) from None
    return out


def json_object(raw: bytes, what: str, data: bytes) -> dict[str, Any]:
    """Parse ``raw`` as a JSON object; raises :class:`EnvelopeError` about ``what`` (quoting ``data``) when
    it is not one."""
    try:
        obj = json.loads(raw)
    except (UnicodeDecodeError, ValueError) as exc:
        raise EnvelopeError(what, f"not JSON: {exc}", data) from None
    if not isinstance(obj, dict):
        raise EnvelopeError(what, "not a JSON object", data)
    return obj


class Fields:
    """Typed, checked reads of a JSON object's fields; a failure names the field."""

    def __init__(self, obj: dict[str, Any], what: str, data: bytes) -> None:
        self._obj, self._what, self._data = obj, what, data

    def _fail(self, name: str, reason: str) -> EnvelopeError:
        return EnvelopeError(self._what, f"field {name!r} {reason}", self._data)

    def text(self, name: str, *, allow_empty: bool = False) -> str:
        """The string field ``name``; it must be present and non-empty unless ``allow_empty`` (then missing
        reads as ``""``)."""
        value = self._obj.get(name, "" if allow_empty else None)
        if not isinstance(value, str):
            raise self._fail(name, "must be a string")
        if not value and not allow_empty:
            raise self._fail(name, "must not be empty")
        return value

    def optional_text(self, name: str) -> str | None:
        """The string field ``name``, or None when it is missing or null."""
        value = self._obj.get(name)
        if value is None:
            return None
        if not isinstance(value, str):
            raise self._fail(name, "must be a string")
        return value

    def integer(self, name: str) -> int:
        """The integer field ``name``: present, not a boolean, not negative."""
        value = self._obj.get(name)
        if not isinstance(value, int) or isinstance(value, bool):
            raise self._fail(name, "must be an integer")
        if value < 0:
            raise self._fail(name, "must not be negative")
        return value
