"""uplink.delivery_board: what one uplink delivered per site, as every console adds it up."""

from __future__ import annotations

import pytest

from fleetlink.uplink.delivery_board import DeliveryBoard, acked_topics
from fleetlink.wire import Record

pytestmark = pytest.mark.unit


def test_running_totals_per_site_and_topic() -> None:
    board = DeliveryBoard()
    board.on_batch("a", "ok", {"fleet.ir": 3, "fleet.imu": 1})
    board.on_batch("a", "ok", {"fleet.ir": 2}, dead_lettered=1)
    board.on_batch("a", "error")
    board.on_batch("b", "refused")
    assert board.sites() == ["a", "b"]
    assert board.figures("a") == {
        "batches": {"ok": 2, "error": 1},
        "records": 6,
        "dead_lettered": 1,
        "topics": {"fleet.ir": 5, "fleet.imu": 1},
    }
    assert board.figures("b") == {"batches": {"refused": 1}, "records": 0, "dead_lettered": 0, "topics": {}}
    assert board.figures("c") is None


def test_acknowledged_records_leave_the_dead_lettered_out() -> None:
    records = [Record(kafka_topic=t, key=b"k", value=b"v", seq=i) for i, t in enumerate(["x", "x", "y"])]
    assert acked_topics(records, set()) == {"x": 2, "y": 1}
    assert acked_topics(records, {1, 2}) == {"x": 1}


def test_bounded_sites_and_topics() -> None:
    board = DeliveryBoard(max_sites=1, max_topics=1)
    board.on_batch("a", "ok", {"t1": 1, "t2": 5})
    board.on_batch("b", "ok", {"t1": 1})
    assert board.sites() == ["a"]
    assert board.figures("a") == {"batches": {"ok": 1}, "records": 1, "dead_lettered": 0, "topics": {"t1": 1}}
