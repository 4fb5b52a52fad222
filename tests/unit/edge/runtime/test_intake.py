"""The intake queue: bounded by items and bytes, never blocking the offering side."""

from __future__ import annotations

import threading

import pytest

from fleetlink.edge.runtime.intake import Intake
from tests.helpers import wait_until


@pytest.mark.parametrize(
    ("max_items", "max_bytes", "sizes", "accepted"),
    [
        (3, 1000, [1, 1, 1, 1, 1], [True, True, True, False, False]),
        (10, 10, [4, 4, 4, 2], [True, True, False, True]),
        (10, 10, [11], [False]),
        (1, 1 << 20, [0, 0], [True, False]),
    ],
)
def test_bounds(max_items: int, max_bytes: int, sizes: list[int], accepted: list[bool]) -> None:
    intake: Intake[int] = Intake(max_items=max_items, max_bytes=max_bytes)
    assert [intake.offer(i, size) for i, size in enumerate(sizes)] == accepted
    stats = intake.stats()
    assert stats.dropped == accepted.count(False)
    assert stats.dropped_bytes == sum(s for s, ok in zip(sizes, accepted, strict=True) if not ok)
    assert stats.queued == accepted.count(True)


def test_fifo_chunks_and_byte_accounting() -> None:
    intake: Intake[str] = Intake(max_items=100, max_bytes=100)
    for i in range(7):
        intake.offer(f"s{i}", 10)
    assert intake.take(3, timeout=0) == ["s0", "s1", "s2"]
    assert intake.stats().queued_bytes == 40
    assert intake.take(10, timeout=0) == ["s3", "s4", "s5", "s6"]
    assert intake.take(10, timeout=0) == []
    stats = intake.stats()
    assert (stats.offered, stats.taken, stats.queued, stats.queued_bytes, stats.high_water) == (7, 7, 0, 0, 7)


def test_forced_items_pass_a_full_queue() -> None:
    intake: Intake[str] = Intake(max_items=1, max_bytes=10)
    assert intake.offer("a", 10)
    assert not intake.offer("b", 1)
    assert intake.offer("event", 1, force=True)
    assert intake.take(5, timeout=0) == ["a", "event"]


def test_close_refuses_new_items_but_keeps_queued_ones() -> None:
    intake: Intake[str] = Intake()
    intake.offer("a")
    intake.close()
    assert not intake.offer("b")
    assert not intake.offer("c", force=True)
    assert intake.take(5, timeout=1) == ["a"]
    assert intake.take(5, timeout=1) == []  # closed and empty: returns at once


def test_take_wakes_up_when_an_item_arrives() -> None:
    intake: Intake[str] = Intake()
    got: list[list[str]] = []
    taker = threading.Thread(target=lambda: got.append(intake.take(5, timeout=10)))
    taker.start()
    intake.offer("x")
    taker.join(5)
    assert not taker.is_alive()
    assert got == [["x"]]


def test_invalid_bounds() -> None:
    with pytest.raises(ValueError, match="positive"):
        Intake(max_items=0)


@pytest.mark.parametrize(
    ("max_items", "max_bytes", "queued", "sizes", "taken"),
    [
        (10, 100, 0, [10, 10, 10], 3),
        (3, 100, 1, [1, 1, 1, 1], 2),  # room for two more items
        (10, 25, 0, [10, 10, 10, 1], 2),  # the third does not fit: it and the rest are dropped
        (10, 100, 0, [], 0),
        (10, 100, 10, [1], 0),
    ],
)
def test_offer_many_queues_in_order_while_it_fits(
    max_items: int, max_bytes: int, queued: int, sizes: list[int], taken: int
) -> None:
    intake: Intake[str] = Intake(max_items=max_items, max_bytes=max_bytes)
    for i in range(queued):
        assert intake.offer(f"q{i}", 0)
    pairs = [(f"s{i}", size) for i, size in enumerate(sizes)]
    assert intake.offer_many(pairs) == taken
    stats = intake.stats()
    assert (stats.offered, stats.dropped, stats.dropped_bytes) == (
        queued + len(sizes),
        len(sizes) - taken,
        sum(sizes[taken:]),
    )
    assert (stats.queued, stats.queued_bytes, stats.high_water) == (
        queued + taken,
        sum(sizes[:taken]),
        queued + taken,
    )
    assert intake.take(100, timeout=0) == [f"q{i}" for i in range(queued)] + [f"s{i}" for i in range(taken)]


def test_offer_many_wakes_a_waiting_taker_and_a_closed_intake_takes_none() -> None:
    intake: Intake[str] = Intake()
    got: list[list[str]] = []
    taker = threading.Thread(target=lambda: got.append(intake.take(5, timeout=10)))
    taker.start()
    assert intake.offer_many([("a", 1), ("b", 1)]) == 2
    taker.join(5)
    assert got == [["a", "b"]]
    intake.close()
    assert intake.offer_many([("c", 1)]) == 0
    assert intake.stats().dropped == 1


def test_offer_many_waits_for_room_that_a_taker_makes() -> None:
    intake: Intake[str] = Intake(max_items=4, max_bytes=1000)
    assert intake.offer_many([(f"a{i}", 1) for i in range(4)]) == 4
    queued: list[int] = []
    offerer = threading.Thread(
        target=lambda: queued.append(intake.offer_many([("b0", 1), ("b1", 1)], wait_s=30))
    )
    offerer.start()
    wait_until(lambda: intake._waiting == 1, 5)  # the offerer waits for room
    assert intake.take(2, timeout=0) == ["a0", "a1"]
    offerer.join(5)
    assert queued == [2]
    assert intake.take(10, timeout=0) == ["a2", "a3", "b0", "b1"]
    assert intake.stats().dropped == 0


def test_offer_many_drops_what_does_not_fit_after_the_wait_and_close_ends_a_wait() -> None:
    intake: Intake[str] = Intake(max_items=3, max_bytes=1000)
    assert intake.offer_many([("a", 1), ("b", 1)]) == 2
    assert intake.offer_many([("c", 1), ("d", 1)], wait_s=0.01) == 1  # room for one after the wait
    assert (intake.stats().dropped, intake.stats().queued) == (1, 3)
    results: list[int] = []
    offerer = threading.Thread(target=lambda: results.append(intake.offer_many([("e", 1)], wait_s=30)))
    offerer.start()
    wait_until(lambda: intake._waiting == 1, 5)
    intake.close()
    offerer.join(5)
    assert results == [0]
    assert intake.stats().dropped == 2
