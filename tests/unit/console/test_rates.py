"""fleetlink.console.rates: counters sampled at poll times -> rates (timelines as tables)."""

from __future__ import annotations

import pytest

from fleetlink.console.rates import RateBoard


@pytest.mark.parametrize(
    ("samples", "expected"),
    [
        ([(0.0, 0)], [None]),
        ([(0.0, 0), (1.0, 10)], [None, 10.0]),
        ([(0.0, 0), (0.2, 5)], [None, None]),  # too short a span to say
        ([(0.0, 0), (0.2, 5), (1.0, 10)], [None, None, 10.0]),
        ([(0.0, 0), (1.0, 10), (2.0, 10)], [None, 10.0, 5.0]),
        # over the window (5 s): the oldest sample at least a window old is the base
        ([(0.0, 0), (1.0, 100), (2.0, 110), (6.0, 150), (7.0, 160)], [None, 100.0, 55.0, 10.0, 10.0]),
        # a counter that went down was reset: it starts again
        ([(0.0, 50), (1.0, 60), (2.0, 5), (3.0, 15)], [None, 10.0, None, 10.0]),
        # a clock that went back starts again too
        ([(5.0, 0), (6.0, 10), (1.0, 20), (2.0, 30)], [None, 10.0, None, 10.0]),
        ([(0.0, 7), (1.0, 7), (2.0, 7)], [None, 0.0, 0.0]),
    ],
)
def test_rate_timelines(samples: list[tuple[float, float]], expected: list[float | None]) -> None:
    board = RateBoard(window_s=5.0, min_span_s=0.5)
    assert [board.rate("c", value, now) for now, value in samples] == expected


def test_counters_are_independent_and_idle_ones_are_forgotten() -> None:
    board = RateBoard(window_s=5.0)
    board.rate("a", 0, 0.0)
    board.rate("b", 0, 0.0)
    assert board.rate("a", 20, 2.0) == 10.0
    assert board.rate("b", 2, 2.0) == 1.0
    assert board.forget_idle(11.0) == 0
    board.rate("a", 30, 11.0)
    assert board.forget_idle(13.0) == 1
    assert len(board) == 1
    assert board.rate("b", 100, 13.0) is None  # history gone: a fresh start
