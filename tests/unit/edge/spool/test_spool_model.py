"""Model-based test: random appends, reads, acks, releases, clean and unclean reopens never lose
an unacked record, never invent one, and keep every batch in seq order."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule

from fleetlink.edge.spool import Spool, SpoolOptions

OPTIONS = SpoolOptions(segment_bytes=4096, max_bytes=64 << 20, fsync="batch", fsync_batch=7, group_records=1)


def crash(spool: Spool) -> None:
    """What a crash leaves: the files as written, no clean-close entry, the lock released."""
    spool._stop.set()
    if spool._flusher is not None:
        spool._flusher.join()
    spool._writer.seal()
    spool._ledger.close()
    os.close(spool._lock_fd)


class SpoolModel(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.directory = Path(tempfile.mkdtemp(prefix="spool-model-"))
        self.spool = Spool(self.directory, OPTIONS).open()
        self.payloads: dict[int, bytes] = {}
        self.unacked: set[int] = set()
        self.flying: dict[int, list[int]] = {}
        self.last_seq = 0

    def teardown(self) -> None:
        self.spool.close()
        shutil.rmtree(self.directory, ignore_errors=True)

    @rule(sizes=st.lists(st.integers(0, 600), min_size=1, max_size=20))
    def append(self, sizes: list[int]) -> None:
        payloads = [os.urandom(n) for n in sizes]
        seqs = self.spool.append_many(payloads)
        for seq, payload in zip(seqs, payloads, strict=True):
            assert seq is not None
            assert seq > self.last_seq
            self.last_seq = seq
            self.payloads[seq] = payload
            self.unacked.add(seq)

    @rule(records=st.integers(1, 40), nbytes=st.integers(1, 5000))
    def read(self, records: int, nbytes: int) -> None:
        batch = self.spool.read_unacked(records, nbytes)
        if batch is None:
            return
        seqs = [r.seq for r in batch.records]
        assert seqs == sorted(seqs)
        assert (batch.first_seq, batch.last_seq) == (seqs[0], seqs[-1])
        for record in batch.records:
            assert record.payload == self.payloads[record.seq]
        assert batch.first_seq not in self.flying
        self.flying[batch.first_seq] = seqs

    @precondition(lambda self: self.flying)
    @rule(data=st.data())
    def ack(self, data: st.DataObject) -> None:
        first = data.draw(st.sampled_from(sorted(self.flying)))
        assert self.spool.ack(first)
        self.unacked -= set(self.flying.pop(first))

    @precondition(lambda self: self.flying)
    @rule(data=st.data())
    def release(self, data: st.DataObject) -> None:
        first = data.draw(st.sampled_from(sorted(self.flying)))
        assert self.spool.release(first)
        del self.flying[first]

    @rule(clean=st.booleans())
    def reopen(self, clean: bool) -> None:
        if clean:
            self.spool.close()
        else:
            crash(self.spool)
        self.spool = Spool(self.directory, OPTIONS).open()
        self.flying.clear()

    @invariant()
    def depth_covers_every_unacked_record(self) -> None:
        stats = self.spool.stats()
        assert stats.depth >= len(self.unacked)
        assert stats.corrupt_skipped == 0
        assert stats.lost_missing == 0  # crashes and clean stops are not damage
        assert stats.damage_unacknowledged == 0
        assert stats.next_seq > self.last_seq

    def drain(self) -> set[int]:
        self.spool.release_all()
        seen: set[int] = set()
        while (batch := self.spool.read_unacked(1000, 1 << 30)) is not None:
            seen.update(r.seq for r in batch.records)
            self.spool.ack(batch.first_seq)
        return seen

    @rule()
    def everything_unacked_comes_back(self) -> None:
        seen = self.drain()
        assert self.unacked <= seen  # no loss
        assert seen <= set(self.payloads)  # nothing invented
        self.unacked.clear()
        self.flying.clear()
        assert self.spool.stats().depth == 0


SpoolModel.TestCase.settings = settings(max_examples=100, stateful_step_count=40, deadline=None)
test_spool_model = SpoolModel.TestCase
