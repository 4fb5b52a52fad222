"""The CDR framing rmw_zenoh payloads carry (rmw_zenoh.md §5): a 4-byte encapsulation header
(``00 01 00 00`` little-endian, ``00 00 00 00`` big-endian) and classic XCDR1 data.

Full (de)serialization is rosbags' job; this module only checks the header and handles the one
message roswire needs without a type store: ``std_msgs/msg/String`` (robot registrations).
"""

from __future__ import annotations

import struct

CDR_BE = b"\x00\x00"
CDR_LE = b"\x00\x01"
HEADER_LE = CDR_LE + b"\x00\x00"


def header_problem(payload: bytes) -> str | None:
    """None when ``payload`` starts with a plain-CDR encapsulation header, else the reason."""
    if len(payload) < 4:
        return f"{len(payload)} bytes: too short for the 4-byte CDR header"
    if payload[:2] not in (CDR_LE, CDR_BE):
        return f"encapsulation {payload[:2].hex()} is not plain CDR (0000 big-endian or 0001 little-endian)"
    return None


def encode_string(text: str) -> bytes:
    """A ``std_msgs/msg/String`` as rmw_serialize writes it."""
    raw = text.encode("utf-8") + b"\x00"
    return HEADER_LE + struct.pack("<I", len(raw)) + raw


def decode_string(payload: bytes) -> str:
    """Read a ``std_msgs/msg/String``; ValueError explains what is wrong."""
    problem = header_problem(payload)
    if problem is not None:
        raise ValueError(problem)
    if len(payload) < 8:
        raise ValueError("no room for the string length")
    fmt = "<I" if payload[:2] == CDR_LE else ">I"
    (length,) = struct.unpack_from(fmt, payload, 4)
    if length == 0 or 8 + length > len(payload):
        raise ValueError(f"string length {length} does not fit in {len(payload) - 8} bytes")
    raw = payload[8 : 8 + length]
    if raw[-1] != 0:
        raise ValueError("string is not NUL-terminated")
    return raw[:-1].decode("utf-8")
