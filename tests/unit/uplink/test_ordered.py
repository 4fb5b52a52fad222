"""Jobs of one key run in arrival order, one at a time; other keys are not held up."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from functools import partial

from fleetlink.uplink.ordered import Gate, KeyedSerialExecutor


def test_one_key_runs_in_order_and_never_concurrently() -> None:
    ran: list[int] = []
    active = 0
    overlap = False
    guard = threading.Lock()

    def job(i: int) -> None:
        nonlocal active, overlap
        with guard:
            active += 1
            overlap = overlap or active > 1
        ran.append(i)
        with guard:
            active -= 1

    with ThreadPoolExecutor(max_workers=8) as pool:
        serial = KeyedSerialExecutor(pool)
        for i in range(2000):
            serial.submit("edge-1/durable", partial(job, i))
    assert ran == list(range(2000))
    assert not overlap


def test_a_blocked_key_does_not_hold_up_another() -> None:
    release = threading.Event()
    other_done = threading.Event()
    with ThreadPoolExecutor(max_workers=2) as pool:
        serial = KeyedSerialExecutor(pool)

        def blocked() -> None:
            release.wait(10)

        serial.submit("a", blocked)
        serial.submit("b", other_done.set)
        assert other_done.wait(5)
        release.set()


def test_a_job_s_gate_holds_its_key_until_it_opens_without_holding_a_worker() -> None:
    gate = Gate()
    ran: list[str] = []
    second_ran = threading.Event()
    other_ran = threading.Event()
    with ThreadPoolExecutor(max_workers=1) as pool:  # one worker: a waiting key must not keep it
        serial = KeyedSerialExecutor(pool)

        def first() -> Gate:
            ran.append("first")
            return gate

        def second() -> None:
            ran.append("second")
            second_ran.set()

        serial.submit("a", first)
        serial.submit("a", second)
        serial.submit("b", other_ran.set)
        assert other_ran.wait(5)
        assert ran == ["first"]
        gate.open()
        assert second_ran.wait(5)
    assert ran == ["first", "second"]


def test_a_gate_open_before_the_job_returns_lets_the_key_go_on() -> None:
    done = threading.Event()

    def opened() -> Gate:
        gate = Gate()
        gate.open()
        gate.open()  # only the first counts
        return gate

    with ThreadPoolExecutor(max_workers=2) as pool:
        serial = KeyedSerialExecutor(pool)
        serial.submit("a", opened)
        serial.submit("a", done.set)
        assert done.wait(5)
