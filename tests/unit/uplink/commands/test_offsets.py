"""Committable offsets when records settle out of order."""

from __future__ import annotations

import pytest

from fleetlink.uplink.commands.offsets import OffsetTracker

TP = ("cmd", 0)


@pytest.mark.parametrize(
    ("steps", "expected"),
    [
        ([("begin", 0)], {}),  # nothing settled yet
        ([("begin", 0), ("done", 0)], {TP: 1}),
        ([("begin", 0), ("begin", 1), ("begin", 2), ("done", 2), ("done", 1)], {}),  # 0 still open
        ([("begin", 0), ("begin", 1), ("begin", 2), ("done", 0), ("done", 2)], {TP: 1}),
        ([("begin", 5), ("begin", 6), ("done", 6), ("done", 5)], {TP: 7}),
        ([("begin", 0), ("done", 0), ("commit", 1)], {}),  # already committed
        ([("begin", 0), ("done", 0), ("commit", 1), ("begin", 1), ("done", 1)], {TP: 2}),
        ([("begin", 3), ("done", 9)], {TP: 3}),  # an unknown offset settles nothing: 3 is read again
    ],
)
def test_committable(steps: list[tuple[str, int]], expected: dict[tuple[str, int], int]) -> None:
    tracker = OffsetTracker()
    for op, offset in steps:
        if op == "begin":
            tracker.begin(TP, offset)
        elif op == "done":
            tracker.done(TP, offset)
        else:
            tracker.committed({TP: offset})
    assert tracker.committable() == expected


def test_partitions_are_independent_and_revoked_ones_forgotten() -> None:
    tracker = OffsetTracker()
    other = ("cmd", 1)
    tracker.begin(TP, 0)
    tracker.begin(other, 10)
    tracker.done(other, 10)
    assert tracker.committable() == {other: 11}
    assert tracker.in_flight() == 1
    tracker.forget([TP])
    assert tracker.in_flight() == 0
    tracker.done(TP, 0)
    assert tracker.committable() == {other: 11}


def test_command_lag_is_the_age_of_the_oldest_record_in_flight() -> None:
    now = [100.0]
    tracker = OffsetTracker(clock=lambda: now[0])
    assert tracker.oldest_age_s() == 0.0
    tracker.begin(("cmd", 0), 5)
    now[0] = 102.0
    tracker.begin(("cmd", 1), 9)
    now[0] = 110.0
    assert tracker.oldest_age_s() == pytest.approx(10.0)
    tracker.done(("cmd", 0), 5)
    assert tracker.oldest_age_s() == pytest.approx(8.0)
    tracker.done(("cmd", 1), 9)
    assert tracker.oldest_age_s() == 0.0
