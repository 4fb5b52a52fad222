"""Spool rows of the reliability matrix (docs/reliability.md) with real processes and files.

Row 8  edge crash:     kill -9 a process appending and acking; reopen intact, resume from the
                       first unacked record, nothing that was taken is lost.
Row 10 torn tail:      truncate / corrupt segments while stopped: detected, counted, skipped,
                       logged with file, offset and seqs.
Row 11 disk full:      a file-size limit (RLIMIT_FSIZE) in the child: writes never half land,
                       the policy applies, the ledger is never half-written, acked data intact.
Row 12 at capacity:    small max_bytes, nothing acked (WAN down): block / drop_oldest /
                       drop_newest as documented, drop counter = lost count, also after kill -9.

The child program is this module: ``python -m tests.fault.test_spool_faults '<json>'``. It
prints one JSON object per line; each is printed only after the call it reports returned.
"""

from __future__ import annotations

import json
import logging
import resource
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from dataclasses import asdict
from pathlib import Path
from typing import Any

import pytest

from fleetlink.edge.errors import SpoolFullError
from fleetlink.edge.spool import Spool, SpoolOptions
from fleetlink.edge.spool.frames import SEGMENT_HEADER_SIZE, Damage, scan
from fleetlink.edge.spool.ledger import parse_ledger
from tests.helpers import wait_until

ROOT = Path(__file__).resolve().parents[2]


# --- the child ----------------------------------------------------------------------------------
def _say(**fields: Any) -> None:
    sys.stdout.write(json.dumps(fields) + "\n")
    sys.stdout.flush()


def _child_crash(spool: Spool, run: str) -> None:
    """Append forever (payload ``run:i``) while a sender reads and acks, keeping 3 in flight."""

    def sender() -> None:
        flying: list[tuple[int, int]] = []
        while True:
            batch = spool.read_unacked(50, 1 << 20)
            if batch is not None:
                flying.append((batch.first_seq, batch.last_seq))
            if len(flying) > 3 or (batch is None and flying):
                first, last = flying.pop(0)
                _say(acking=[first, last])  # announced before: a kill may land in between
                spool.ack(first)

    threading.Thread(target=sender, daemon=True).start()
    i = 0
    while True:
        seqs = spool.append_many([f"{run}:{i + k}".encode() for k in range(20)])
        _say(taken=[seqs[0], seqs[-1], i])
        i += 20


def _child_fill(spool: Spool, count: int, batch: int) -> None:
    for start in range(0, count, batch):
        try:
            payloads = [f"{start + k}".encode() * 20 for k in range(min(batch, count - start))]
            results = spool.append_many(payloads)
        except SpoolFullError as exc:
            _say(full=exc.taken)
            break
        _say(results=results)


def _child_disk_full(spool: Spool) -> None:
    """500 records; ack one batch; the file-size limit drops to 1 byte (nothing can grow);
    100 more records and one more ack; the limit is lifted; 10 more records."""
    _child_fill(spool, 500, 50)
    acked = []
    for _ in range(2):
        batch = spool.read_unacked(100, 1 << 20)
        assert batch is not None
        acked.append([batch.first_seq, batch.last_seq])
        if len(acked) == 1:
            spool.ack(batch.first_seq)
            soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
            resource.setrlimit(resource.RLIMIT_FSIZE, (1, hard))
            _child_fill(spool, 100, 10)
        else:
            spool.ack(batch.first_seq)
            resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
    _say(acked=acked)
    _child_fill(spool, 10, 10)


def child_main(spec: dict[str, Any]) -> None:
    logging.basicConfig(level=logging.INFO, stream=sys.stderr)
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a file-size limit must fail writes, not kill us
    if spec.get("fsize"):
        resource.setrlimit(resource.RLIMIT_FSIZE, (spec["fsize"], resource.RLIM_INFINITY))
    spool = Spool(spec["dir"], SpoolOptions(**spec["options"])).open()
    mode = spec["mode"]
    if mode == "crash":
        _child_crash(spool, spec["run"])
    elif mode == "fill":
        _child_fill(spool, spec["count"], spec["batch"])
        spool.flush()  # on disk, and the ledger knows how far
    elif mode == "disk_full":
        _child_disk_full(spool)
    _say(stats=asdict(spool.stats()))
    if spec.get("close"):
        spool.close()
        _say(closed=True)
    sys.stdin.readline()  # wait to be killed (or for stdin to close)


# --- the test side ------------------------------------------------------------------------------
class Child:
    """A child process whose JSON lines are collected by a thread as they arrive."""

    def __init__(self, spec: dict[str, Any]) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tests.fault.test_spool_faults", json.dumps(spec)],
            cwd=ROOT,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.lines: list[dict[str, Any]] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(json.loads(line))

    def of(self, key: str) -> list[Any]:
        return [line[key] for line in list(self.lines) if key in line]

    def wait_for(self, key: str, count: int = 1, timeout: float = 20) -> None:
        def ready() -> bool:
            if self.proc.poll() is not None and len(self.of(key)) < count:
                stderr = self.proc.stderr.read() if self.proc.stderr else ""
                raise AssertionError(f"child exited {self.proc.returncode} early:\n{stderr}")
            return len(self.of(key)) >= count

        wait_until(ready, timeout=timeout, message=f"{count} {key!r} line(s) from the child")

    def kill(self) -> str:
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=10)
        self._reader.join(timeout=10)
        return self.proc.stderr.read() if self.proc.stderr else ""


@pytest.fixture
def children() -> Iterator[list[Child]]:
    started: list[Child] = []
    yield started
    for child in started:
        if child.proc.poll() is None:
            child.kill()


def drain(directory: Path, options: SpoolOptions) -> tuple[dict[int, bytes], dict[str, Any]]:
    with Spool(directory, options) as spool:
        stats = asdict(spool.stats())
        records: dict[int, bytes] = {}
        while (batch := spool.read_unacked(1000, 1 << 22)) is not None:
            for record in batch.records:
                assert record.seq not in records
                records[record.seq] = record.payload
            spool.ack(batch.first_seq)
    return records, stats


def segments_are_clean(directory: Path) -> bool:
    for path in directory.glob("*.seg"):
        data = path.read_bytes()
        if any(
            isinstance(e, Damage)
            for e in scan(data, SEGMENT_HEADER_SIZE, len(data), max_len=1 << 24, final=True, copy=False)
        ):
            return False
    return True


# --- row 8 --------------------------------------------------------------------------------------
CRASH_OPTIONS: dict[str, Any] = {
    "segment_bytes": 65536,
    "max_bytes": 64 << 20,
    "fsync": "interval",
    "fsync_interval_ms": 50,
}


def test_row8_kill9_while_appending_and_acking_loses_nothing_taken(
    tmp_path: Path, children: list[Child]
) -> None:
    expected: dict[int, bytes] = {}
    acking: list[tuple[int, int]] = []
    last_seq = 0
    for run in ("a", "b", "c", "d", "e"):
        child = Child({"dir": str(tmp_path), "options": CRASH_OPTIONS, "mode": "crash", "run": run})
        children.append(child)
        child.wait_for("taken", 300)
        child.wait_for("acking", 10)
        child.kill()
        for first, last, index in child.of("taken"):
            assert first > last_seq  # seqs never go back, across restarts either
            last_seq = last
            for seq in range(first, last + 1):
                expected[seq] = f"{run}:{index + seq - first}".encode()
        acking.extend(tuple(pair) for pair in child.of("acking"))
    records, stats = drain(tmp_path, SpoolOptions(**CRASH_OPTIONS))

    def maybe_acked(seq: int) -> bool:
        return any(first <= seq <= last for first, last in acking)

    assert stats["corrupt_skipped"] <= 5  # at most one torn tail per kill, of a record never taken
    assert all(expected.get(seq, payload) == payload for seq, payload in records.items())  # none altered
    missing = [seq for seq in expected if seq not in records and not maybe_acked(seq)]
    assert missing == []  # every record taken and not acked is still there
    resent = [seq for seq in records if maybe_acked(seq)]
    assert len(resent) <= 4 * 50  # duplicates stay within the in-flight window
    assert stats["depth"] == len(records)


# --- row 10 -------------------------------------------------------------------------------------
FILL_OPTIONS: dict[str, Any] = {"segment_bytes": 8192, "max_bytes": 64 << 20}


def frames_of(path: Path) -> list[tuple[int, int, range]]:
    """``(offset, end, seqs)`` of every frame (a group of records) in a segment file."""
    data = path.read_bytes()
    return [
        (f.offset, f.end, range(f.seq, f.last_seq + 1))
        for f in scan(data, SEGMENT_HEADER_SIZE, len(data), max_len=1 << 24, final=True, copy=False)
        if not isinstance(f, Damage)
    ]


def test_row10_torn_tail_and_flipped_bit_are_counted_skipped_and_named(
    tmp_path: Path, children: list[Child], caplog: pytest.LogCaptureFixture
) -> None:
    child = Child({"dir": str(tmp_path), "options": FILL_OPTIONS, "mode": "fill", "count": 400, "batch": 40})
    children.append(child)
    child.wait_for("stats")
    child.kill()
    taken = [seq for results in child.of("results") for seq in results]
    segments = sorted(tmp_path.glob("*.seg"))
    assert len(segments) >= 3
    first, last = segments[0], segments[-1]
    offset, end, flipped = frames_of(first)[1]
    data = bytearray(first.read_bytes())
    data[end - 3] ^= 0x10  # a payload bit of the second group
    first.write_bytes(bytes(data))
    tail_offset, tail_end, torn = frames_of(last)[-1]
    with last.open("r+b") as handle:
        handle.truncate(tail_end - 7)  # the last group loses its end, as in a torn write
    caplog.set_level(logging.ERROR)
    records, stats = drain(tmp_path, SpoolOptions(**FILL_OPTIONS))
    assert sorted(records) == [s for s in taken if s not in flipped and s not in torn]
    assert stats["corrupt_skipped"] == len(flipped) + len(torn)  # every record of both groups, exactly
    size = end - offset
    assert f"corrupt data in {first} at offset {offset} ({size} bytes: checksum mismatch)" in caplog.text
    assert f"seqs {flipped[0]}..{flipped[-1]}" in caplog.text
    # the ledger knew the last group was on disk: not a write cut short, a segment cut short
    assert f"segment cut short in {last} at offset {tail_offset}" in caplog.text
    assert f"seqs {torn[0]}..{torn[-1]}" in caplog.text
    assert len([r for r in caplog.records if " at offset " in r.getMessage()]) == 2  # a line per range
    assert segments_are_clean(tmp_path)  # the torn tail was cut away, the rest was acked away


# --- row 11 -------------------------------------------------------------------------------------
def test_row11_file_size_limit_rotates_segments_and_never_half_writes(
    tmp_path: Path, children: list[Child]
) -> None:
    limit = 20_000
    options: dict[str, Any] = {"segment_bytes": 1 << 20, "max_bytes": 64 << 20}
    child = Child(
        {
            "dir": str(tmp_path),
            "options": options,
            "mode": "fill",
            "count": 3000,
            "batch": 50,
            "fsize": limit,
            "close": True,
        }
    )
    children.append(child)
    child.wait_for("closed")
    taken = [seq for results in child.of("results") for seq in results]
    assert taken == list(range(1, 3001))  # nothing refused: a fresh segment takes what the old could not
    (stats,) = child.of("stats")
    assert stats["disk_full"] == 0  # a per-file limit is handled by rotating, before any policy
    assert all(p.stat().st_size <= limit for p in tmp_path.glob("*.seg"))
    assert len(list(tmp_path.glob("*.seg"))) >= 10
    assert segments_are_clean(tmp_path)
    records, _ = drain(tmp_path, SpoolOptions(**options))
    assert records == {i + 1: f"{i}".encode() * 20 for i in range(3000)}


@pytest.mark.parametrize("policy", ["block", "drop_oldest", "drop_newest"])
def test_row11_disk_full_follows_the_policy_and_keeps_the_ledger_whole(
    tmp_path: Path, children: list[Child], policy: str
) -> None:
    options: dict[str, Any] = {
        "segment_bytes": 8192,
        "max_bytes": 64 << 20,
        "policy": policy,
        "block_timeout_s": 0.2,
    }
    child = Child({"dir": str(tmp_path), "options": options, "mode": "disk_full", "close": True})
    children.append(child)
    child.wait_for("closed")
    results = [seq for batch in child.of("results") for seq in batch]
    taken = [seq for seq in results if seq is not None]
    (acked,) = child.of("acked")
    (stats,) = child.of("stats")
    assert stats["disk_full"] >= 1
    if policy == "block":
        assert child.of("full") == [0]  # nothing taken while full; the caller still holds the record
        assert stats["block_timeouts"] == 1
        assert len(results) == 510  # the 100 were never taken, so never reported
    else:
        assert results.count(None) == 100
        assert stats["dropped_newest"] == 100
    assert results[-10:] == taken[-10:]  # once there is room again, records are taken again
    ledger = parse_ledger((tmp_path / "ledger").read_bytes())
    assert ledger.damaged_at is None  # never a half-written ledger
    records, _ = drain(tmp_path, SpoolOptions(**options))
    done = {s for first, last in acked for s in range(first, last + 1)}
    unacked = [s for s in taken if s not in done]
    assert sorted(records) == unacked[stats["dropped_oldest"] :]  # the drop counter is the lost count
    if policy != "drop_oldest":
        assert stats["dropped_oldest"] == 0


# --- row 12 -------------------------------------------------------------------------------------
@pytest.mark.parametrize("policy", ["block", "drop_oldest", "drop_newest"])
def test_row12_capacity_policies_survive_a_kill(tmp_path: Path, children: list[Child], policy: str) -> None:
    options: dict[str, Any] = {
        "segment_bytes": 4096,
        "max_bytes": 16384,
        "policy": policy,
        "block_timeout_s": 0.2,
    }
    child = Child({"dir": str(tmp_path), "options": options, "mode": "fill", "count": 1000, "batch": 50})
    children.append(child)
    child.wait_for("stats")
    child.kill()
    results = [seq for batch in child.of("results") for seq in batch]
    taken = [seq for seq in results if seq is not None]
    (stats,) = child.of("stats")
    records, after = drain(tmp_path, SpoolOptions(**options))
    assert stats["bytes"] <= 16384
    if policy == "drop_oldest":
        assert taken == list(range(1, 1001))
        assert stats["dropped_oldest"] > 0
        assert sorted(records) == taken[stats["dropped_oldest"] :]
    elif policy == "drop_newest":
        assert results.count(None) == stats["dropped_newest"] > 0
        assert sorted(records) == taken
    else:
        (full,) = child.of("full")  # the call that timed out had taken its first `full` records
        assert stats["block_timeouts"] == 1
        assert sorted(records) == list(range(1, len(taken) + full + 1))
    assert after["depth"] == len(records)
    assert stats["appended"] == len(records) + stats["dropped_oldest"]


if __name__ == "__main__":
    child_main(json.loads(sys.argv[1]))
