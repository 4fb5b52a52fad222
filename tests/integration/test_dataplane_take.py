"""The data plane's take against a real Zenoh router: a take that waits for company ends its wait
as soon as it has all it may take, not when its window is over."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest
import zenoh

from fleetlink.common.zenoh_options import ZenohOptions
from fleetlink.edge.runtime.dataplane import NativeSource, python_config_json
from fleetlink.roswire.session import ros_session_config

KEY = "fleetlink/test/take"
WINDOW_S = 5.0
"""The take's collect window: far longer than publishing the samples takes."""


@pytest.fixture
def source(zenoh_router: str) -> Iterator[NativeSource]:
    config = ros_session_config(ZenohOptions(mode="client", connect=(zenoh_router,)))
    source = NativeSource(
        python_config_json(config), max_items=10_000, max_bytes=1 << 24, max_value_bytes=1 << 20
    )
    source.subscribe(f"{KEY}/**")
    yield source
    source.close()


def _take(source: NativeSource, max_samples: int, timeout_s: float, collect_s: float) -> int:
    """Samples taken: ``DataPlane.take`` with a collect window of ``collect_s`` (not busy)."""
    _groups, _slow, _lanes, count, _oldest, _marks = source.plane.take(
        max_samples, timeout_s, 1 << 20, 2000, 1 << 20, collect_s, 0.0, 0.0
    )
    return int(count)


def test_a_take_that_has_all_it_may_take_does_not_wait_out_its_window(
    source: NativeSource, zenoh_router: str
) -> None:
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", f'["{zenoh_router}"]')
    with zenoh.open(config) as session:
        publisher = session.declare_publisher(f"{KEY}/a")
        # until the router routes this session's samples to the data plane's subscription
        deadline = time.monotonic() + 10
        while _take(source, 1000, 0.1, 0.0) == 0:
            assert time.monotonic() < deadline, "the data plane never received a sample"
            publisher.put(b"hello")
        while _take(source, 1000, 0.2, 0.0):  # what is still on its way
            pass

        taken: list[tuple[int, float]] = []
        taking = threading.Event()

        def take() -> None:
            taking.set()
            began = time.monotonic()
            count = _take(source, 50, WINDOW_S, WINDOW_S)
            taken.append((count, time.monotonic() - began))

        publisher.put(b"first")  # the take collects from this one on, up to 50
        taker = threading.Thread(target=take)
        taker.start()
        assert taking.wait(10)
        for n in range(49):
            publisher.put(n.to_bytes(4, "little"))
        taker.join(WINDOW_S * 3)
        assert not taker.is_alive()

    count, waited_s = taken[0]
    assert count == 50
    # the fiftieth sample woke the take: without that it returned only when its 5 s were over
    assert waited_s < WINDOW_S / 2, f"the take waited {waited_s:.2f} s for samples it already had"
