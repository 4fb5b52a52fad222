"""A failed batch fences its stream: later batches wait until it comes again (or the fence expires)."""

from __future__ import annotations

from fleetlink.uplink.stream_fence import Fenced, StreamFence


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


STREAM = ("site-a", "edge-1", "durable")


def test_later_batches_wait_until_the_failed_one_comes_again() -> None:
    clock = Clock()
    fence = StreamFence(hold_s=60, clock=clock)
    assert fence.check(STREAM, 1) is None
    fence.failed(STREAM, 101)
    clock.now += 2
    assert fence.check(STREAM, 201) == Fenced(101, 2.0)
    assert fence.check(STREAM, 301) == Fenced(101, 2.0)
    assert fence.check(("site-a", "edge-2", "durable"), 201) is None  # other streams go on
    assert fence.check(STREAM, 101) is None  # the failed batch again: it goes, and lifts the fence
    assert fence.check(STREAM, 201) is None
    assert len(fence) == 0


def test_the_earliest_failure_counts() -> None:
    fence = StreamFence(clock=Clock())
    fence.failed(STREAM, 201)
    fence.failed(STREAM, 101)
    fence.failed(STREAM, 301)
    assert fence.check(STREAM, 201) == Fenced(101, 0.0)
    assert fence.check(STREAM, 90) is None  # an edge that starts again from an earlier seq


def test_a_fence_lasts_at_most_hold_s() -> None:
    clock = Clock()
    fence = StreamFence(hold_s=60, clock=clock)
    fence.failed(STREAM, 101)
    clock.now += 60
    assert fence.check(STREAM, 201) is not None
    clock.now += 0.5
    assert fence.check(STREAM, 201) is None  # the failed batch never came back: not stopped for good
    assert len(fence) == 0
    fence.failed(STREAM, 301)
    clock.now += 61
    fence.failed(STREAM, 401)  # the old fence expired: the new failure counts
    assert fence.check(STREAM, 501) == Fenced(401, 0.0)


def test_fences_are_bounded() -> None:
    fence = StreamFence(max_streams=3, clock=Clock())
    for edge in range(5):
        fence.failed(("site-a", f"edge-{edge}", "durable"), 10)
    assert len(fence) == 3
    assert fence.check(("site-a", "edge-0", "durable"), 20) is None  # the oldest went first
    assert fence.check(("site-a", "edge-4", "durable"), 20) is not None


def test_an_earlier_batch_in_hand_before_the_fence_goes_and_leaves_it_up() -> None:
    clock = Clock()
    fence = StreamFence(clock=clock)
    queued_at = clock.now  # batch 1.. arrived and waits its turn
    clock.now += 1
    fence.failed(STREAM, 11)  # then batch 11.. was answered busy, unread
    assert fence.check(STREAM, 1, arrived=queued_at) is None  # the earlier batch goes
    assert fence.check(STREAM, 21, arrived=clock.now) == Fenced(11, 0.0)  # the fence is still up
    assert fence.check(STREAM, 11, arrived=clock.now) is None  # batch 11.. again lifts it
    assert len(fence) == 0


def test_a_fence_that_may_not_evict_is_not_set_when_full() -> None:
    fence = StreamFence(max_streams=2, clock=Clock())
    fence.failed(("s", "e", "a"), 1)
    fence.failed(("s", "e", "b"), 1)
    fence.failed(("s", "e", "c"), 1, evict=False)  # a flood of new streams pushes nobody out
    assert fence.check(("s", "e", "a"), 5) == Fenced(1, 0.0)
    assert fence.check(("s", "e", "b"), 5) == Fenced(1, 0.0)
    assert fence.check(("s", "e", "c"), 5) is None
    fence.failed(("s", "e", "a"), 0, evict=False)  # a stream already fenced moves to the earlier seq
    assert fence.check(("s", "e", "a"), 1) == Fenced(0, 0.0)
