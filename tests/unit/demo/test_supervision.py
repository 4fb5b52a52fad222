"""The demo's stream app is started again after an error, a bounded number of times."""

from __future__ import annotations

import threading

import pytest

from fleetlink.demo.supervision import run_restarting


def test_an_app_that_fails_twice_then_runs_is_restarted_twice() -> None:
    calls: list[int] = []
    heard: list[tuple[str, int]] = []

    def run() -> None:
        calls.append(len(calls))
        if len(calls) <= 2:
            raise KeyError(f"changelog {len(calls)}")

    run_restarting(run, attempts=3, stop=threading.Event(), on_restart=lambda e, n: heard.append((str(e), n)))
    assert calls == [0, 1, 2]
    assert heard == [("'changelog 1'", 1), ("'changelog 2'", 2)]


def test_the_last_error_propagates_after_the_last_attempt() -> None:
    def run() -> None:
        raise RuntimeError("always")

    heard: list[int] = []
    with pytest.raises(RuntimeError, match="always"):
        run_restarting(run, attempts=2, stop=threading.Event(), on_restart=lambda _e, n: heard.append(n))
    assert heard == [1]


def test_an_error_while_stopping_ends_it_quietly() -> None:
    stop = threading.Event()
    calls: list[int] = []

    def run() -> None:
        calls.append(1)
        stop.set()
        raise RuntimeError("closing")

    run_restarting(run, attempts=3, stop=stop, on_restart=lambda _e, _n: pytest.fail("no restart"))
    assert calls == [1]
