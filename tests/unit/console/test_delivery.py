"""fleetlink.console.delivery: every uplink's delivery figures added up."""

from __future__ import annotations

from typing import Any

import pytest

from fleetlink.console.delivery import delivery_view, merged_latency
from fleetlink.console.rates import RateBoard

pytestmark = pytest.mark.unit


def answer(uplink: str, site: str, acked: int, samples: list[float]) -> dict[str, Any]:
    return {
        "uplink": uplink,
        "site": site,
        "batches": {"ok": len(samples), "error": 1},
        "records": acked,
        "dead_lettered": 1,
        "topics": {"fleet.ir": acked},
        "latency": {"batches": len(samples), "max_ms": max(samples, default=0), "samples_ms": samples},
    }


def test_totals_rates_and_latency_over_every_uplink() -> None:
    board = RateBoard()
    delivery_view(board, [answer("u1", "a", 100, []), answer("u2", "a", 50, [])], now=10.0)
    view = delivery_view(
        board, [answer("u1", "a", 120, [1.0, 2.0, 3.0]), answer("u2", "a", 60, [10.0])], now=12.0
    )
    assert view["uplink_count"] == 2
    assert view["batches"] == {"ok": 4, "error": 2}
    assert (view["records"], view["dead_lettered"]) == (180, 2)
    assert view["topics"]["fleet.ir"] == {"acked": 180, "rate": 15.0}  # 10/s + 5/s
    assert view["rate"] == 15.0
    assert view["latency"] == {"batches": 4, "p50_ms": 2.0, "p95_ms": 10.0, "max_ms": 10.0, "window_s": 60.0}


def test_an_uplink_that_restarts_does_not_make_the_rate_jump() -> None:
    board = RateBoard()
    delivery_view(board, [answer("u1", "a", 1000, [])], now=10.0)
    delivery_view(board, [answer("u1", "a", 1010, [])], now=12.0)
    view = delivery_view(board, [answer("u1", "a", 1020, []), answer("u9", "a", 3, [])], now=14.0)
    assert view["topics"]["fleet.ir"]["rate"] == 5.0  # the new uplink has no rate yet, nothing negative


def test_no_answers_and_malformed_ones() -> None:
    view = delivery_view(RateBoard(), [{"site": "a"}, {"uplink": 3}], now=1.0)
    assert (view["uplink_count"], view["records"], view["latency"], view["rate"]) == (0, 0, None, None)
    assert merged_latency([{"latency": {"batches": 2}}]) is None
