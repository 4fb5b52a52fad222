"""Samples that outrun their robot's registration: held per topic in order, bounded, given up."""

from __future__ import annotations

from fleetlink.edge.runtime.early import EarlySamples
from fleetlink.roswire.subscriber import RosSample

S = 1_000_000_000


def sample(topic: str, seq: int, size: int = 10) -> RosSample:
    return RosSample(topic, "std_msgs/msg/String", "RIHS01_", b"x" * size, seq, None, None, "k", 0)


def test_released_per_topic_in_arrival_order() -> None:
    early = EarlySamples(2 * S, max_samples=10, max_bytes=1000)
    for seq in (1, 2, 3):
        assert early.add(sample("/a/chat", seq), now_ns=seq)
    assert early.add(sample("/b/chat", 9), now_ns=4)
    assert (len(early), early.bytes, early.waiting()) == (4, 40, {"/a/chat": 3, "/b/chat": 1})
    assert [s.seq for s in early.release("/a/chat")] == [1, 2, 3]
    assert not early.holds("/a/chat")
    assert early.holds("/b/chat")
    assert (len(early), early.bytes, early.stats.held, early.stats.released) == (1, 10, 4, 3)
    assert early.release("/a/chat") == []


def test_a_topic_whose_first_sample_waited_in_vain_is_given_up_whole() -> None:
    early = EarlySamples(2 * S, max_samples=10, max_bytes=1000)
    early.add(sample("/a/chat", 1), now_ns=0)
    early.add(sample("/a/chat", 2), now_ns=S)
    early.add(sample("/b/chat", 1), now_ns=S)
    assert early.expired(2 * S - 1) == []
    assert [s.seq for s in early.expired(2 * S)] == [1, 2]  # the later one goes with the first
    assert not early.add(sample("/a/chat", 3), now_ns=2 * S)  # given up: not held again...
    assert early.stats.overflow == 0
    early.retry()  # ...until the mappings change
    assert early.add(sample("/a/chat", 4), now_ns=2 * S)
    assert (early.stats.expired, early.waiting()) == (2, {"/b/chat": 1, "/a/chat": 1})


def test_bounded_in_samples_and_bytes_and_off_at_zero() -> None:
    early = EarlySamples(S, max_samples=2, max_bytes=25)
    assert early.add(sample("/a/chat", 1), 0)
    assert early.add(sample("/a/chat", 2), 0)
    assert not early.add(sample("/a/chat", 3), 0)  # a third sample
    early.release("/a/chat")
    assert early.add(sample("/a/chat", 4, size=20), 0)
    assert not early.add(sample("/a/chat", 5, size=6), 0)  # 26 bytes
    assert early.stats.overflow == 2
    off = EarlySamples(0, max_samples=2, max_bytes=25)
    assert not off.add(sample("/a/chat", 1), 0)
    assert off.stats.overflow == 0
