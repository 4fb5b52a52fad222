"""Byte-level helpers the generated converters call: Avro varints, array blocks, validation.

Helpers know offsets but not type names: they raise :class:`WireError` / :class:`WireRange`,
which the generated converter turns into ``DecodeError`` / ``ValueRangeError`` with the type
name and the raw input.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import numpy as np


class WireError(Exception):
    """Malformed input at ``offset`` (internal; converted by the codec)."""

    def __init__(self, offset: int, reason: str) -> None:
        super().__init__(offset, reason)
        self.offset = offset
        self.reason = reason


class WireRange(Exception):  # noqa: N818 (internal signal, converted to ValueRangeError)
    """A value out of range for ``field`` (internal; converted by the codec)."""

    def __init__(self, field: str, value: object, reason: str, offset: int) -> None:
        super().__init__(field, value, reason, offset)
        self.field = field
        self.value = value
        self.reason = reason
        self.offset = offset


def _varint(u: int) -> bytes:
    out = bytearray()
    while u >= 0x80:
        out.append((u & 0x7F) | 0x80)
        u >>= 7
    out.append(u)
    return bytes(out)


_SMALL = 1 << 14
_VARINTS: tuple[bytes, ...] = tuple(_varint(u) for u in range(_SMALL))
ZERO = b"\x00"


def zz(value: int) -> bytes:
    """Avro int/long encoding (zigzag varint) of a signed 64-bit integer."""
    u = (value << 1) ^ (value >> 63)
    if u < _SMALL:
        return _VARINTS[u]
    return _varint(u)


def count(n: int) -> bytes:
    """The block header of an Avro array with ``n`` items (nothing for an empty array)."""
    if n == 0:
        return b""
    if n < 0x2000:
        return _VARINTS[n << 1]
    return _varint(n << 1)


def zz_many(values: Sequence[int]) -> bytes:
    """Concatenated zigzag varints of ``values``."""
    return b"".join(map(zz, values))


def read_long(buf: bytes, pos: int) -> tuple[int, int]:
    """Decode an Avro int/long at ``pos``; returns (value, position after it)."""
    try:
        b = buf[pos]
        if b < 0x80:
            return (b >> 1) ^ -(b & 1), pos + 1
        u = b & 0x7F
        shift = 7
        i = pos + 1
        while True:
            b = buf[i]
            i += 1
            u |= (b & 0x7F) << shift
            if b < 0x80:
                break
            shift += 7
            if shift > 63:
                raise WireError(pos, "varint longer than 10 bytes")
    except IndexError:
        raise WireError(len(buf), f"truncated varint starting at offset {pos}") from None
    return (u >> 1) ^ -(u & 1), i


def read_span(buf: bytes, pos: int) -> tuple[int, int]:
    """Where the content of the Avro ``bytes``/``string`` at ``pos`` starts and ends."""
    length, start = read_long(buf, pos)
    end = start + length
    if length < 0 or end > len(buf):
        raise WireError(pos, f"byte length {length} does not fit in the {len(buf)}-byte input")
    return start, end


def read_bytes(buf: bytes, pos: int) -> tuple[memoryview, int]:
    """An Avro ``bytes`` value as a view into ``buf`` (no copy): (content, position after it)."""
    start, end = read_span(buf, pos)
    return memoryview(buf)[start:end], end


def read_text(buf: bytes, pos: int, bound: int) -> tuple[bytes, int]:
    """An Avro ``string`` checked for UTF-8 and the ROS bound (0 = none): (UTF-8 bytes, pos after)."""
    start, end = read_span(buf, pos)
    raw = buf[start:end]
    check_utf8(raw, start)
    if bound and len(raw) > bound:
        raise WireError(pos, f"string of {len(raw)} bytes exceeds its bound {bound}")
    return raw, end


def check_utf8(raw: bytes, offset: int) -> None:
    """Raise ``WireError`` if ``raw`` (found at ``offset``) is not valid UTF-8."""
    if not raw.isascii():
        try:
            raw.decode()
        except UnicodeDecodeError as exc:
            raise WireError(offset + exc.start, f"invalid UTF-8: {exc.reason}") from None


def utf8(raw: bytes, offset: int) -> str:
    """``raw`` (found at ``offset``) decoded as UTF-8, or ``WireError`` at the first bad byte."""
    try:
        return raw.decode()
    except UnicodeDecodeError as exc:
        raise WireError(offset + exc.start, f"invalid UTF-8: {exc.reason}") from None


def check_bools(raw: bytes | memoryview, offset: int) -> None:
    """Raise ``WireError`` unless every byte of ``raw`` is 0 or 1."""
    rest = bytes(raw).translate(None, b"\x00\x01")
    if rest:
        bad = next(i for i, b in enumerate(raw) if b > 1)
        raise WireError(offset + bad, f"invalid bool byte 0x{raw[bad]:02x}")


def check_uint64(values: Sequence[int], field: str, offset: int) -> None:
    """Raise ``WireRange`` for a uint64 that an Avro long cannot hold."""
    for i, value in enumerate(values):
        if value > 0x7FFF_FFFF_FFFF_FFFF:
            reason = "uint64 above 2**63-1 does not fit an Avro long"
            raise WireRange(f"{field}[{i}]", value, reason, offset + 8 * i)


def swap(buf: bytes, start: int, nbytes: int, size: int) -> bytes:
    """Big-endian items of ``size`` bytes -> little-endian."""
    if size == 1:
        return buf[start : start + nbytes]
    return np.frombuffer(buf, f">u{size}", nbytes // size, start).byteswap().tobytes()


def read_array_raw(buf: bytes, pos: int, itemsize: int) -> tuple[int, bytes | memoryview, int]:
    """An Avro array of fixed-size items (float/double/boolean): (count, raw items, pos after)."""
    total = 0
    parts: list[memoryview] = []
    view = memoryview(buf)
    while True:
        n, pos = read_long(buf, pos)
        if n == 0:
            break
        if n < 0:
            n = -n
            _, pos = read_long(buf, pos)
        end = pos + n * itemsize
        if end > len(buf):
            raise WireError(pos, f"array block of {n} items does not fit in the {len(buf)}-byte input")
        parts.append(view[pos:end])
        total += n
        pos = end
    if len(parts) == 1:
        return total, parts[0], pos
    return total, b"".join(parts), pos


def read_array_longs(buf: bytes, pos: int) -> tuple[list[int], int]:
    """An Avro array of int/long items: (values, pos after)."""
    values: list[int] = []
    while True:
        n, pos = read_long(buf, pos)
        if n == 0:
            return values, pos
        if n < 0:
            n = -n
            _, pos = read_long(buf, pos)
        if n > len(buf) - pos:
            raise WireError(pos, f"array block of {n} items does not fit in the {len(buf)}-byte input")
        for _ in range(n):
            value, pos = read_long(buf, pos)
            values.append(value)


def read_block(buf: bytes, pos: int) -> tuple[int, int]:
    """The item count of the next Avro array block (0 = end): (count, pos of the first item)."""
    n, pos = read_long(buf, pos)
    if n < 0:
        n = -n
        _, pos = read_long(buf, pos)
    if n > len(buf) - pos:
        raise WireError(pos, f"array block of {n} items does not fit in the {len(buf)}-byte input")
    return n, pos


def pack_ints(fmt: str, values: Sequence[int], kind_range: tuple[int, int], field: str, offset: int) -> bytes:
    """Little-endian CDR items of ``fmt`` (one struct character), range-checked."""
    lo, hi = kind_range
    if values and (min(values) < lo or max(values) > hi):
        bad = next(v for v in values if v < lo or v > hi)
        raise WireRange(field, bad, f"outside [{lo}, {hi}]", offset)
    return struct.pack(f"<{len(values)}{fmt}", *values)


def truncated(buf: bytes, base: int, table: Sequence[tuple[int, int, str]]) -> None:
    """Raise ``WireError`` for the first item of ``table`` (start, end, field) past the input's end."""
    for start, end, field in table:
        if base + end > len(buf):
            raise WireError(
                min(base + start, len(buf)),
                f"truncated: {field} needs bytes {base + start}..{base + end - 1}, input has {len(buf)}",
            )


# What malformed input can make the generated code raise besides WireError / WireRange.
UNEXPECTED: tuple[type[Exception], ...] = (IndexError, struct.error, ValueError, OverflowError, MemoryError)


def offset_of(exc: BaseException) -> int:
    """Best-effort input offset of an unexpected error: the largest position a converter had reached."""
    tb = exc.__traceback__
    best = 0
    while tb is not None:
        frame = tb.tb_frame
        if frame.f_code.co_filename.startswith("<"):
            for name, value in frame.f_locals.items():
                if name[:1] in "pdea" and name[1:].isdigit() and isinstance(value, int):
                    best = max(best, value)
        tb = tb.tb_next
    return best
