"""Embedded stores as the edge spool would use them, for the comparison in bench_spool.py.

Each store keeps records by seq and offers what the spool does: append one record, append a
group, read the oldest unacknowledged ones, acknowledge (delete) up to a seq, reopen. The
settings are the durable ones each store documents:

* SQLite in WAL mode (Python's ``sqlite3``), one row per record (``seq INTEGER PRIMARY KEY,
  payload BLOB``) or one row per group of records (``first_seq, count, payload``);
  ``synchronous=NORMAL`` (the WAL is fsynced at checkpoints: a process crash loses nothing
  committed, a power cut may lose the last commits, like the spool's ``interval``) or ``FULL``
  (an fsync per commit, like ``always``);
* the fleetlink spool itself behind the same interface (``SpoolStore``);
* LMDB (``lmdb``, when installed), one entry per group keyed by its first seq (big-endian), with
  ``sync=True`` (an fsync per transaction) or ``sync=False`` plus an ``env.sync()`` every 100 ms
  (like ``interval``).

Also ``python bench/spool_alternatives.py STORE DIR``: a child that appends groups of 10 records
(payload = its seq) flat out and prints each group's last seq after its commit returned, until
it is killed (the kill -9 recovery check).
"""

from __future__ import annotations

import importlib
import sqlite3
import struct
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

try:
    lmdb: Any = importlib.import_module("lmdb")
except ImportError:  # pragma: no cover - an optional comparison
    lmdb = None
HAVE_LMDB = lmdb is not None

_U64 = struct.Struct(">Q")
_LEN = struct.Struct("<I")


class Store(Protocol):
    name: str

    def append(self, payload: bytes) -> int: ...
    def append_many(self, payloads: Sequence[bytes]) -> int: ...
    def read_groups(self, max_records: int) -> list[tuple[int, int, bytes]]: ...
    def ack(self, last_seq: int) -> None: ...
    def close(self) -> None: ...


def pack(payloads: Sequence[bytes]) -> bytes:
    return b"".join(_LEN.pack(len(p)) + p for p in payloads)


def unpack(blob: bytes) -> list[bytes]:
    out, pos = [], 0
    while pos < len(blob):
        (n,) = _LEN.unpack_from(blob, pos)
        out.append(blob[pos + 4 : pos + 4 + n])
        pos += 4 + n
    return out


class SqliteRows:
    """One row per record."""

    def __init__(self, directory: Path, synchronous: str = "NORMAL") -> None:
        self.name = f"sqlite WAL rows, synchronous={synchronous}"
        self.db = sqlite3.connect(directory / "spool.db", isolation_level=None, check_same_thread=False)
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.execute(f"PRAGMA synchronous={synchronous}")
        self.db.execute("CREATE TABLE IF NOT EXISTS records (seq INTEGER PRIMARY KEY, payload BLOB)")
        row = self.db.execute("SELECT max(seq) FROM records").fetchone()
        self.next_seq = (row[0] or 0) + 1

    def append(self, payload: bytes) -> int:
        seq = self.next_seq
        self.db.execute("INSERT INTO records VALUES (?, ?)", (seq, payload))  # autocommit: one transaction
        self.next_seq += 1
        return seq

    def append_many(self, payloads: Sequence[bytes]) -> int:
        first = self.next_seq
        self.db.execute("BEGIN")
        self.db.executemany(
            "INSERT INTO records VALUES (?, ?)", [(first + i, p) for i, p in enumerate(payloads)]
        )
        self.db.execute("COMMIT")
        self.next_seq += len(payloads)
        return first + len(payloads) - 1

    def read_groups(self, max_records: int) -> list[tuple[int, int, bytes]]:
        """Records, oldest first (a row is one record: a group of one)."""
        rows = self.db.execute("SELECT seq, payload FROM records ORDER BY seq LIMIT ?", (max_records,))
        return [(seq, 1, payload) for seq, payload in rows]

    def ack(self, last_seq: int) -> None:
        self.db.execute("DELETE FROM records WHERE seq <= ?", (last_seq,))

    def count(self) -> int:
        return int(self.db.execute("SELECT count(*) FROM records").fetchone()[0])

    def seqs(self) -> set[int]:
        return {row[0] for row in self.db.execute("SELECT seq FROM records")}

    def close(self) -> None:
        self.db.close()


class SqliteGroups(SqliteRows):
    """One row per group of records (what the spool's frames are)."""

    def __init__(self, directory: Path, synchronous: str = "NORMAL") -> None:
        self.name = f"sqlite WAL groups, synchronous={synchronous}"
        self.db = sqlite3.connect(directory / "spool.db", isolation_level=None, check_same_thread=False)
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.execute(f"PRAGMA synchronous={synchronous}")
        self.db.execute(
            "CREATE TABLE IF NOT EXISTS groups (first_seq INTEGER PRIMARY KEY, n INTEGER, payload BLOB)"
        )
        row = self.db.execute("SELECT max(first_seq + n) FROM groups").fetchone()
        self.next_seq = row[0] or 1

    def append(self, payload: bytes) -> int:
        return self.append_many([payload])

    def append_many(self, payloads: Sequence[bytes]) -> int:
        return self.append_group(pack(payloads), len(payloads))

    def append_group(self, group: bytes, count: int) -> int:
        first = self.next_seq
        self.db.execute("INSERT INTO groups VALUES (?, ?, ?)", (first, count, group))
        self.next_seq += count
        return first + count - 1

    def read_groups(self, max_records: int) -> list[tuple[int, int, bytes]]:
        """Whole groups, oldest first, up to ``max_records`` records (as the spool's batches)."""
        out: list[tuple[int, int, bytes]] = []
        taken = 0
        for first, n, blob in self.db.execute("SELECT first_seq, n, payload FROM groups ORDER BY first_seq"):
            out.append((first, n, blob))
            taken += n
            if taken >= max_records:
                break
        return out

    def ack(self, last_seq: int) -> None:
        self.db.execute("DELETE FROM groups WHERE first_seq + n - 1 <= ?", (last_seq,))

    def count(self) -> int:
        return int(self.db.execute("SELECT coalesce(sum(n), 0) FROM groups").fetchone()[0])

    def seqs(self) -> set[int]:
        return {
            s
            for first, n in self.db.execute("SELECT first_seq, n FROM groups")
            for s in range(first, first + n)
        }


class LmdbGroups:
    """One entry per group, keyed by its first seq (big-endian: keys sort by seq)."""

    def __init__(self, directory: Path, sync: bool = True) -> None:
        if lmdb is None:
            raise RuntimeError("lmdb is not installed (pip install lmdb)")
        self.name = f"lmdb groups, sync={'every commit' if sync else 'every 100 ms'}"
        self.env = lmdb.open(str(directory), map_size=8 << 30, sync=sync, metasync=sync, writemap=False)
        self.next_seq = 1
        with self.env.begin() as txn:
            cursor = txn.cursor()
            if cursor.last():
                first = _U64.unpack(cursor.key())[0]
                self.next_seq = first + _LEN.unpack_from(cursor.value(), 0)[0]
        self._stop = threading.Event()
        self._syncer: threading.Thread | None = None
        if not sync:
            self._syncer = threading.Thread(target=self._sync_loop, daemon=True)
            self._syncer.start()

    def _sync_loop(self) -> None:
        while not self._stop.wait(0.1):
            self.env.sync(True)

    def append(self, payload: bytes) -> int:
        return self.append_many([payload])

    def append_many(self, payloads: Sequence[bytes]) -> int:
        return self.append_group(pack(payloads), len(payloads))

    def append_group(self, group: bytes, count: int) -> int:
        first = self.next_seq
        with self.env.begin(write=True) as txn:
            txn.put(_U64.pack(first), _LEN.pack(count) + group)
        self.next_seq += count
        return first + count - 1

    def read_groups(self, max_records: int) -> list[tuple[int, int, bytes]]:
        out: list[tuple[int, int, bytes]] = []
        taken = 0
        with self.env.begin() as txn:
            for key, value in txn.cursor():
                (n,) = _LEN.unpack_from(value, 0)
                out.append((_U64.unpack(key)[0], n, value[4:]))
                taken += n
                if taken >= max_records:
                    break
        return out

    def ack(self, last_seq: int) -> None:
        with self.env.begin(write=True) as txn:
            cursor = txn.cursor()
            while cursor.first():
                first = _U64.unpack(cursor.key())[0]
                if first + _LEN.unpack_from(cursor.value(), 0)[0] - 1 > last_seq:
                    break
                cursor.delete()

    def count(self) -> int:
        return len(self.seqs())

    def seqs(self) -> set[int]:
        with self.env.begin() as txn:
            return {
                s
                for key, value in txn.cursor()
                for s in range(_U64.unpack(key)[0], _U64.unpack(key)[0] + _LEN.unpack_from(value, 0)[0])
            }

    def close(self) -> None:
        self._stop.set()
        if self._syncer is not None:
            self._syncer.join()
        self.env.close()


class SpoolStore:
    """The fleetlink spool behind the same small interface (``fsync: interval``)."""

    def __init__(self, directory: Path) -> None:
        from fleetlink.edge.spool import Spool, SpoolOptions

        self.name = "fleetlink spool, fsync=interval"
        self.spool = Spool(directory, SpoolOptions(max_bytes=4 << 30, segment_bytes=64 << 20)).open()
        self._flying: list[tuple[int, int]] = []

    def append_many(self, payloads: Sequence[bytes]) -> int:
        seqs = self.spool.append_many(payloads)
        last = seqs[-1]
        assert last is not None
        return last

    def append(self, payload: bytes) -> int:
        return self.append_many([payload])

    def append_group(self, group: bytes, count: int) -> int:
        taken = self.spool.append_group(group)
        assert taken == count
        return self.spool.stats().next_seq - 1

    def read_groups(self, max_records: int) -> list[tuple[int, int, bytes]]:
        batch = self.spool.read_unacked(max_records, 1 << 24)
        if batch is None:
            return []
        self._flying.append((batch.first_seq, batch.last_seq))
        return [(g.first_seq, g.records, g.group) for g in batch.groups]

    def ack(self, last_seq: int) -> None:
        while self._flying and self._flying[0][1] <= last_seq:
            self.spool.ack(self._flying.pop(0)[0])

    def count(self) -> int:
        return self.spool.stats().depth

    def seqs(self) -> set[int]:
        out: set[int] = set()
        while (batch := self.spool.read_unacked(10_000, 1 << 26)) is not None:
            out.update(r.seq for r in batch.records)
        return out

    def close(self) -> None:
        self.spool.close()


def open_store(kind: str, directory: Path) -> SqliteRows | LmdbGroups | SpoolStore:
    if kind == "spool":
        return SpoolStore(directory)
    if kind == "sqlite-rows":
        return SqliteRows(directory)
    if kind == "sqlite-groups":
        return SqliteGroups(directory)
    if kind == "lmdb":
        return LmdbGroups(directory, sync=False)
    raise ValueError(kind)


def crash_child(kind: str, directory: Path) -> None:
    store = open_store(kind, directory)
    seq = 1
    while True:
        last = store.append_many([str(seq + i).encode() for i in range(10)])
        seq = last + 1
        sys.stdout.write(f"{last}\n")
        sys.stdout.flush()


if __name__ == "__main__":
    crash_child(sys.argv[1], Path(sys.argv[2]))
