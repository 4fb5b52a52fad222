"""Publisher marks: the last ``(publisher GID, sequence number)`` whose sample reached the spool.

After a crash the edge must tell what its robots published that never reached the spool. The
data plane follows each publisher's rmw_zenoh sequence numbers; the spool keeps, *in the same
write as the records they describe*, the last sequence number of every publisher whose samples
those records hold (a marks block in the frame of the last group of that write). So after
``kill -9`` the marks say exactly what reached the spool: a frame is whole or torn away with its
records. At the next start the data plane is seeded with them and counts what each publisher's
first sample skipped (``lost_at_restart``): samples the edge had received but not spooled when
it stopped, and samples published while it was down.

Marks in a segment leave with it; before a segment is deleted the spool writes every mark it
knows to a snapshot file (``marks``), so opening = the snapshot, then the marks of the segments
left (the highest seq per GID wins: a publisher's seqs only grow, a restarted publisher has a
new GID). At most ``MAX_MARKS`` publishers are remembered (the least recently updated go first).

Encodings (little-endian): a marks block is ``{ gid 16 bytes | seq i64 } * count | count u32``
(the count last: in a frame the block follows the group, so the group's checksum, computed before
the spool's lock is taken, carries on over it); the snapshot file is ``FLMARKS1 | marks block |
crc32 of both``.
"""

from __future__ import annotations

import logging
import struct
import zlib
from collections import deque
from collections.abc import Iterable
from itertools import repeat
from operator import itemgetter
from pathlib import Path

from fleetlink.common.durable import write_atomically

log = logging.getLogger(__name__)

GID_SIZE = 16
_ENTRY = struct.Struct("<16sq")
_COUNT = struct.Struct("<I")
ENTRY_SIZE = _ENTRY.size  # 24
MAX_MARKS = 65536
"""Publishers remembered (the data plane follows as many)."""
SNAPSHOT_NAME = "marks"
SNAPSHOT_MAGIC = b"FLMARKS1"

Mark = tuple[bytes, int]
_GID = itemgetter(0)


class MarksError(ValueError):
    """A marks block that does not decode."""


def encode_marks(marks: Iterable[Mark]) -> bytes:
    """A marks block (GIDs of any other length than 16 bytes are left out)."""
    pack = _ENTRY.pack
    body = [pack(gid, seq) for gid, seq in marks if len(gid) == GID_SIZE]
    return b"".join(body) + _COUNT.pack(len(body))


def merge_marks(*blocks: bytes) -> bytes:
    """One marks block of ``blocks`` (empty ones welcome): the highest seq per GID; ``b""`` when
    there is none."""
    found: dict[bytes, int] = {}
    for block in blocks:
        if block:
            for gid, seq in decode_marks(block):
                known = found.get(gid)
                found[gid] = seq if known is None or seq > known else known
    return encode_marks(found.items()) if found else b""


def marks_block_size(data: bytes | memoryview, end: int | None = None) -> int:
    """The size of the marks block ending at ``end`` (default: the end of ``data``), read from
    its count; raises ``MarksError``."""
    end = len(data) if end is None else end
    if end < _COUNT.size:
        raise MarksError("a marks block is shorter than its count")
    (count,) = _COUNT.unpack_from(data, end - _COUNT.size)
    size = int(_COUNT.size + count * ENTRY_SIZE)
    if size > end:
        raise MarksError(f"a marks block of {count} entries runs past its frame")
    return size


def decode_marks(block: bytes | memoryview) -> list[Mark]:
    """The marks of a marks block; raises ``MarksError`` when ``block`` is not exactly one block."""
    size = marks_block_size(block)
    if size != len(block):
        raise MarksError(f"{len(block) - size} bytes before a marks block")
    return list(_ENTRY.iter_unpack(memoryview(block)[: size - _COUNT.size]))


class MarkBook:
    """The marks known, bounded (least recently updated forgotten first). Not thread-safe."""

    def __init__(self, limit: int = MAX_MARKS) -> None:
        self.limit = limit
        self._marks: dict[bytes, int] = {}
        self.changed = False
        """Updated since the last ``snapshot``."""

    def update(self, marks: Iterable[Mark]) -> None:
        """Keep the highest seq per publisher GID; beyond ``limit`` the least recently updated go."""
        book = self._marks
        for gid, seq in marks:
            known = book.pop(gid, None)
            book[gid] = seq if known is None else max(known, seq)
            self.changed = True
        while len(book) > self.limit:
            del book[next(iter(book))]

    def add_block(self, block: bytes) -> None:
        """``update`` with a marks block (the spool's hot path: a block per write, with a mark per
        publisher in it). A later mark of a GID replaces the one known: the data plane's marks of
        a publisher only grow (a duplicate never lowers one)."""
        if not block:
            return
        entries = decode_marks(block)
        book = self._marks
        deque(map(book.pop, map(_GID, entries), repeat(None)), maxlen=0)  # most recently updated last
        book.update(entries)
        self.changed = True
        while len(book) > self.limit:
            del book[next(iter(book))]

    def items(self) -> list[Mark]:
        """Every known mark, least recently updated first."""
        return list(self._marks.items())

    def __len__(self) -> int:
        return len(self._marks)


def write_snapshot(path: Path, marks: Iterable[Mark]) -> None:
    """Replace the snapshot file atomically (temp file, fsync, rename); raises ``OSError``."""
    body = SNAPSHOT_MAGIC + encode_marks(marks)
    data = body + zlib.crc32(body).to_bytes(4, "little")
    write_atomically(path, data)


def read_snapshot(path: Path) -> list[Mark] | None:
    """The marks in a snapshot file; ``[]`` when there is none, ``None`` when it is damaged."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return []
    body, crc = data[:-4], data[-4:]
    if len(data) < len(SNAPSHOT_MAGIC) + 8 or not body.startswith(SNAPSHOT_MAGIC):
        return None
    if zlib.crc32(body).to_bytes(4, "little") != crc:
        return None
    try:
        return decode_marks(body[len(SNAPSHOT_MAGIC) :])
    except MarksError:
        return None
