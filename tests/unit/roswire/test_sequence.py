"""Per-publisher sequence tracking."""

from __future__ import annotations

import pytest

from fleetlink.roswire.sequence import SeqStatus, SequenceTracker

A, B = b"a" * 16, b"b" * 16

CASES: list[tuple[str, list[tuple[bytes, int]], list[tuple[SeqStatus, int]], tuple[int, int, int]]] = [
    (
        "in order",
        [(A, 1), (A, 2), (A, 3)],
        [(SeqStatus.FIRST, 0), (SeqStatus.NEXT, 0), (SeqStatus.NEXT, 0)],
        (0, 0, 0),
    ),
    ("gap of two", [(A, 1), (A, 4)], [(SeqStatus.FIRST, 0), (SeqStatus.GAP, 2)], (1, 2, 0)),
    (
        "late joiner starts anywhere",
        [(A, 57), (A, 58)],
        [(SeqStatus.FIRST, 0), (SeqStatus.NEXT, 0)],
        (0, 0, 0),
    ),
    (
        "duplicate and reorder",
        [(A, 1), (A, 2), (A, 2), (A, 1), (A, 3)],
        [
            (SeqStatus.FIRST, 0),
            (SeqStatus.NEXT, 0),
            (SeqStatus.DUPLICATE, 0),
            (SeqStatus.DUPLICATE, 0),
            (SeqStatus.NEXT, 0),
        ],
        (0, 0, 2),
    ),
    (
        "publishers tracked apart",
        [(A, 1), (B, 7), (A, 2), (B, 9)],
        [(SeqStatus.FIRST, 0), (SeqStatus.FIRST, 0), (SeqStatus.NEXT, 0), (SeqStatus.GAP, 1)],
        (1, 1, 0),
    ),
]


@pytest.mark.parametrize(("label", "steps", "expected", "totals"), CASES, ids=[c[0] for c in CASES])
def test_sequences(
    label: str,
    steps: list[tuple[bytes, int]],
    expected: list[tuple[SeqStatus, int]],
    totals: tuple[int, int, int],
) -> None:
    tracker = SequenceTracker()
    got = [(r.status, r.missing) for r in (tracker.observe(g, s) for g, s in steps)]
    assert got == expected, label
    assert (tracker.gaps, tracker.missing, tracker.duplicates) == totals


def test_bounded_number_of_sources() -> None:
    tracker = SequenceTracker(max_sources=2)
    for i in range(5):
        tracker.observe(bytes([i]) * 16, 1)
    assert tracker.sources == 2
    assert tracker.last(bytes([0]) * 16) is None
    assert tracker.last(bytes([4]) * 16) == 1
