"""The spool's frames and ledger, byte by byte (pure parsing, no spool object)."""

from __future__ import annotations

import struct
import zlib

import pytest

from fleetlink.edge.spool.frames import (
    HEADER_SIZE,
    SEGMENT_HEADER_SIZE,
    Damage,
    Frame,
    decode_segment_header,
    encode_frame,
    encode_segment_header,
    frame_at,
    peek_timestamp,
    scan,
)
from fleetlink.edge.spool.ledger import ACK, CLEAN, ENTRY_SIZE, RESERVE, encode_entry, parse_ledger

MAX = 1 << 20


def frames(*seqs: int) -> bytes:
    return b"".join(encode_frame(s, 1000 + s, f"payload-{s}".encode()) for s in seqs)


def events(buf: bytes, *, final: bool = True, after: int = -1) -> list[Frame | Damage]:
    return list(scan(buf, 0, len(buf), max_len=MAX, final=final, after_seq=after))


def test_frame_layout_is_as_documented() -> None:
    frame = encode_frame(7, 1234, b"abc")
    assert len(frame) == HEADER_SIZE + 3 == 31
    magic, flags, length, seq, ts, crc = struct.unpack_from("<HHIQqI", frame)
    assert (magic, flags, length, seq, ts) == (0x5BF1, 0, 3, 7, 1234)
    assert crc == zlib.crc32(frame[:24], zlib.crc32(b"abc"))
    assert frame[28:] == b"abc"
    assert peek_timestamp(frame) == 1234
    assert peek_timestamp(b"\x00" * 28) is None


def test_segment_header() -> None:
    header = encode_segment_header(42)
    assert len(header) == SEGMENT_HEADER_SIZE
    assert header[:8] == b"FLSPOOL1"
    assert decode_segment_header(header) == 42
    assert decode_segment_header(b"XXSPOOL1" + header[8:]) is None
    assert decode_segment_header(header[:10]) is None


def test_clean_scan_yields_every_frame_in_order() -> None:
    found = events(frames(1, 2, 3))
    assert [(f.seq, f.timestamp_ms, f.payload) for f in found if isinstance(f, Frame)] == [
        (1, 1001, b"payload-1"),
        (2, 1002, b"payload-2"),
        (3, 1003, b"payload-3"),
    ]
    assert all(isinstance(f, Frame) for f in found)


@pytest.mark.parametrize("where", [0, 4, 10, 20, 26, 28, 35])
def test_any_flipped_byte_is_damage_and_scanning_resumes(where: int) -> None:
    good = frames(1, 2, 3)
    second = len(encode_frame(1, 1001, b"payload-1"))
    broken = bytearray(good)
    broken[second + where] ^= 0x40
    found = events(bytes(broken))
    assert [f.seq for f in found if isinstance(f, Frame)] == [1, 3]
    (damage,) = [d for d in found if isinstance(d, Damage)]
    assert damage.offset == second
    assert damage.end == 2 * second


def test_torn_tail_is_damage_only_when_final() -> None:
    data = frames(1, 2)[:-5]
    found = events(data)
    assert isinstance(found[-1], Damage)
    assert "truncated frame" in found[-1].reason
    assert found[-1].end == len(data)
    partial = events(data, final=False)
    assert [type(f) for f in partial] == [Frame]  # stops quietly before the incomplete frame


def test_seq_going_backwards_is_damage() -> None:
    found = events(frames(5, 3, 6))
    assert [f.seq for f in found if isinstance(f, Frame)] == [5, 6]
    assert "does not follow 5" in next(d for d in found if isinstance(d, Damage)).reason
    assert [f.seq for f in events(frames(5, 6), after=5) if isinstance(f, Frame)] == [6]


def test_oversized_length_is_damage() -> None:
    frame = bytearray(encode_frame(1, 0, b"x" * 10))
    struct.pack_into("<I", frame, 4, MAX + 1)
    assert "exceeds" in str(frame_at(bytes(frame), 0, len(frame), MAX))


def test_garbage_with_no_frame_is_one_damage() -> None:
    assert events(b"\xf1\x5b" + b"\x00" * 100) == [Damage(0, 102, "checksum mismatch")]
    assert events(b"\x00" * 50) == [Damage(0, 50, "bad frame magic")]


def test_ledger_keeps_last_state_and_stops_at_torn_entry() -> None:
    data = encode_entry(ACK, 5) + encode_entry(RESERVE, 100) + encode_entry(ACK, 9)
    state = parse_ledger(data)
    assert (state.ack_mark, state.reserved, state.clean_next_seq, state.damaged_at) == (9, 100, None, None)
    torn = data + encode_entry(ACK, 50)[:7]
    state = parse_ledger(torn)
    assert (state.ack_mark, state.damaged_at) == (9, 3 * ENTRY_SIZE)
    flipped = bytearray(data)
    flipped[2 * ENTRY_SIZE + 4] ^= 1
    assert parse_ledger(bytes(flipped)).ack_mark == 5


def test_ledger_clean_close_counts_only_when_last() -> None:
    assert parse_ledger(encode_entry(ACK, 3) + encode_entry(CLEAN, 10)).clean_next_seq == 10
    assert parse_ledger(encode_entry(CLEAN, 10) + encode_entry(ACK, 3)).clean_next_seq is None
    assert parse_ledger(b"").fresh
    assert not parse_ledger(encode_entry(ACK, 1)).fresh
