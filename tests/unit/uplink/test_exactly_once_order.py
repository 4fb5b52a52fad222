"""Which exactly-once batches an uplink may write: none past records the edge may still send."""

from __future__ import annotations

from fleetlink.uplink.exactly_once.writer import unsettled_gap
from fleetlink.wire import Batch


def head(first_seq: int, acked: int) -> Batch:
    return Batch("s", "e", "durable", first_seq, (), origin=7, acked=acked)


def test_the_next_batch_after_the_mark_is_no_gap() -> None:
    assert unsettled_gap(10, head(11, 0)) is None
    assert unsettled_gap(10, head(5, 0)) is None  # sent again: its records up to the mark are skipped


def test_seqs_the_edge_may_still_send_are_a_gap() -> None:
    assert unsettled_gap(10, head(21, 10)) == (11, 20)  # 11..20 in flight, or failed
    assert unsettled_gap(10, head(31, 20)) == (21, 30)  # 11..20 done at the edge, 21..30 not
    assert unsettled_gap(0, head(21, 0)) == (1, 20)  # a new stream's first batch is not its first


def test_seqs_the_edge_settled_are_no_gap() -> None:
    assert unsettled_gap(10, head(500, 499)) is None  # evicted, corrupt or skipped at a restart
    assert unsettled_gap(0, head(1_048_580, 1_048_579)) is None
