"""Byte-level building blocks of the wire format: fixed structs, length-prefixed text, and a
bounds-checked reader whose every failure is a ``WireError`` carrying the offset."""

from __future__ import annotations

import struct

from fleetlink.wire.errors import WireError

VERSION = 1
U16 = struct.Struct("<H")
U32 = struct.Struct("<I")
U64 = struct.Struct("<Q")


def str16(text: str) -> bytes:
    """``text`` as UTF-8 behind its u16 length; raises ``WireError`` when longer than 65535 bytes."""
    data = text.encode("utf-8")
    if len(data) > 0xFFFF:
        raise WireError(f"text of {len(data)} bytes does not fit a 16-bit length")
    return U16.pack(len(data)) + data


class Reader:
    """Bounds-checked reads from a buffer; every failure is a ``WireError`` with the offset."""

    __slots__ = ("data", "end", "pos")

    def __init__(self, data: bytes | memoryview, pos: int = 0, end: int | None = None) -> None:
        self.data = data
        self.pos = pos
        self.end = len(data) if end is None else end

    def take(self, n: int, what: str) -> bytes:
        """The next ``n`` bytes; ``what`` names them in the error when fewer are left."""
        if n > self.end - self.pos:
            raise WireError(f"truncated {what}: needs {n} bytes, {self.end - self.pos} left", offset=self.pos)
        out = bytes(self.data[self.pos : self.pos + n])
        self.pos += n
        return out

    def unpack(self, fmt: struct.Struct, what: str) -> tuple[int, ...]:
        """The values of struct ``fmt`` at the current position, which moves past them."""
        if fmt.size > self.end - self.pos:
            raise WireError(f"truncated {what}", offset=self.pos)
        values = fmt.unpack_from(self.data, self.pos)
        self.pos += fmt.size
        return values

    def text(self, what: str, wide: bool = False) -> str:
        """UTF-8 text behind a u16 length (u32 when ``wide``)."""
        (n,) = self.unpack(U32 if wide else U16, f"{what} length")
        start = self.pos
        try:
            return self.take(n, what).decode("utf-8")
        except UnicodeDecodeError:
            raise WireError(f"{what} is not valid UTF-8", offset=start) from None

    def blob(self, what: str) -> bytes:
        """Bytes behind a u32 length."""
        (n,) = self.unpack(U32, f"{what} length")
        return self.take(n, what)

    def done(self, what: str) -> None:
        """Raise ``WireError`` unless every byte up to the end was read; ``what`` names what they held."""
        if self.pos != self.end:
            raise WireError(f"{self.end - self.pos} unexpected trailing bytes after {what}", offset=self.pos)
