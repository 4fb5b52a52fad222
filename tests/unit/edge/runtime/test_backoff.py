"""Retry backoff: exponential, bounded, jittered within [base/2, base]."""

from __future__ import annotations

import random

import pytest

from fleetlink.edge.runtime.backoff import Backoff


class FixedRandom(random.Random):
    def __init__(self, value: float) -> None:
        super().__init__(0)
        self.value = value

    def random(self) -> float:
        return self.value


@pytest.mark.parametrize(
    ("jitter", "expected"),
    [
        (0.0, [0.1, 0.2, 0.4, 0.8, 1.0, 1.0]),  # lowest draw: half of each base
        (1.0, [0.2, 0.4, 0.8, 1.6, 2.0, 2.0]),  # highest draw: the base itself, capped at max
        (0.5, [0.15, 0.3, 0.6, 1.2, 1.5, 1.5]),
    ],
)
def test_delays(jitter: float, expected: list[float]) -> None:
    backoff = Backoff(0.2, 2.0, rng=FixedRandom(jitter))
    assert [round(backoff.next_delay(), 6) for _ in expected] == expected


def test_reset_and_huge_attempt_counts() -> None:
    backoff = Backoff(0.5, 30.0, rng=FixedRandom(1.0))
    for _ in range(200):
        assert 0.25 <= backoff.next_delay() <= 30.0
    assert backoff.base(10_000) == 30.0
    backoff.reset()
    assert backoff.next_delay() == 0.5


@pytest.mark.parametrize(("low", "high"), [(0.0, 1.0), (2.0, 1.0), (-1.0, 1.0)])
def test_invalid(low: float, high: float) -> None:
    with pytest.raises(ValueError, match="backoff"):
        Backoff(low, high)
