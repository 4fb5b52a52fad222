"""Groups in the spool and the memory buffer: records appended together are written, read back,
acknowledged and lost (counted) together; a group never makes a batch pass its limits."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from fleetlink.edge.errors import SpoolFullError
from fleetlink.edge.spool import MemoryBuffer, RecordBuffer, Spool, SpoolOptions
from fleetlink.edge.spool.frames import HEADER_SIZE, SEGMENT_HEADER_SIZE
from fleetlink.wire.groups import encode_group, group_payloads
from tests.unit.edge.spool.writes import count_writes

GROUPED = SpoolOptions(segment_bytes=1 << 20, max_bytes=8 << 20, group_records=100, group_bytes=1 << 20)


def payloads(n: int, start: int = 0) -> list[bytes]:
    return [f"record-{i:06d}".encode() * 3 for i in range(start, start + n)]


def drain(buffer: RecordBuffer, max_records: int) -> list[list[bytes]]:
    batches = []
    while (batch := buffer.read_unacked(max_records, 1 << 30)) is not None:
        batches.append([r.payload for r in batch.records])
        buffer.ack(batch.first_seq)
    return batches


def open_buffer(kind: str, tmp_path: Path) -> RecordBuffer:
    """The durable spool or the memory buffer, both with groups of at most 100 records."""
    if kind == "spool":
        return Spool(tmp_path, GROUPED).open()
    return MemoryBuffer(first_seq=1, group_records=100)


@pytest.mark.parametrize("kind", ["spool", "memory"])
def test_appended_groups_come_back_whole_within_the_batch_limit(kind: str, tmp_path: Path) -> None:
    buffer = open_buffer(kind, tmp_path)
    try:
        buffer.append_many(payloads(250))  # groups of 100, 100, 50
        assert buffer.append_group(encode_group(payloads(30, 250))) == 30
        batches = drain(buffer, 240)
        assert [len(b) for b in batches] == [200, 80]  # whole groups; the third would pass 240
        assert [p for b in batches for p in b] == payloads(280)
        assert buffer.stats().acked == 280
    finally:
        buffer.close()


def test_a_group_above_the_limits_is_split(tmp_path: Path) -> None:
    with Spool(tmp_path, GROUPED) as spool:
        assert spool.append_group(encode_group(payloads(250))) == 250
        batch = spool.read_unacked(10_000, 1 << 30)
        assert batch is not None
        assert [g.records for g in batch.groups] == [100, 100, 50]
        assert [p for g in batch.groups for p in group_payloads(g.group)] == payloads(250)


@pytest.mark.parametrize("kind", ["spool", "memory"])
def test_several_groups_are_taken_in_one_call_in_order(kind: str, tmp_path: Path) -> None:
    buffer = open_buffer(kind, tmp_path)
    try:
        made = [encode_group(payloads(3)), encode_group(payloads(150, 3)), encode_group(payloads(1, 153))]
        assert buffer.append_groups(made) == 154
        batch = buffer.read_unacked(10_000, 1 << 30)
        assert batch is not None
        assert [g.records for g in batch.groups] == [3, 100, 50, 1]  # the middle one split
        assert [r.seq for r in batch.records] == list(range(1, 155))
        assert [r.payload for r in batch.records] == payloads(154)
    finally:
        buffer.close()


def test_groups_taken_together_are_one_write(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    writes = count_writes(monkeypatch)
    with Spool(tmp_path, GROUPED) as spool:
        spool.append_groups(
            [encode_group(payloads(2)), encode_group(payloads(2, 2)), encode_group(payloads(1, 4))]
        )
        assert spool.stats().depth == 5
    assert writes == [3]  # three frames, one write


def test_damage_in_a_group_loses_its_records_counted_exactly(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with Spool(tmp_path, GROUPED) as spool:
        spool.append_many(payloads(300))  # three frames of 100
    segment = next(tmp_path.glob("*.seg"))
    data = bytearray(segment.read_bytes())
    second = SEGMENT_HEADER_SIZE + (len(data) - SEGMENT_HEADER_SIZE) // 3
    data[second + HEADER_SIZE + 500] ^= 0x40  # a bit inside the second group
    segment.write_bytes(bytes(data))
    caplog.set_level(logging.ERROR)
    with Spool(tmp_path, GROUPED) as spool:
        assert spool.stats().corrupt_skipped == 100
        assert f"corrupt data in {segment} at offset {second}" in caplog.text
        batches = drain(spool, 1000)
    assert [p for b in batches for p in b] == payloads(100) + payloads(100, 200)


def test_block_refuses_a_whole_group_and_drop_newest_counts_its_records(tmp_path: Path) -> None:
    small = SpoolOptions(segment_bytes=4096, max_bytes=8192, group_records=10, policy="drop_newest")
    with Spool(tmp_path / "d", small) as spool:
        taken = sum(spool.append_group(encode_group(payloads(10, 10 * i))) for i in range(40))
        stats = spool.stats()
        assert taken + stats.dropped_newest == 400
        assert stats.dropped_newest % 10 == 0
        assert stats.dropped_newest > 0
    blocking = SpoolOptions(segment_bytes=4096, max_bytes=8192, group_records=10, block_timeout_s=0.05)
    with Spool(tmp_path / "b", blocking) as spool:
        taken = 0
        for i in range(40):  # fill it: each group taken whole
            if spool.stats().bytes + 600 > 8192:
                break
            taken += spool.append_group(encode_group(payloads(10, 10 * i)))
        with pytest.raises(SpoolFullError) as info:
            spool.append_group(encode_group(payloads(10, 1000)))
        assert info.value.taken == 0  # the refused group is refused whole
        assert spool.stats().block_timeouts == 1
        assert spool.stats().appended == taken


def test_groups_larger_than_a_segment_frame_are_split_to_fit(tmp_path: Path) -> None:
    options = SpoolOptions(segment_bytes=8192, max_bytes=1 << 20, group_bytes=1 << 20)  # (the WAN's limit)
    payloads = [bytes([n % 251]) * 300 for n in range(100)]  # 30 KB: far beyond one 8 KiB segment
    with Spool(tmp_path, options) as spool:
        assert spool.append_group(encode_group(payloads)) == 100
        assert spool.append_many(payloads) == list(range(101, 201))
        seen: list[bytes] = []
        while (batch := spool.read_unacked(1000, 1 << 20)) is not None:
            seen.extend(r.payload for r in batch.records)
            spool.ack(batch.first_seq)
    assert seen == payloads + payloads
