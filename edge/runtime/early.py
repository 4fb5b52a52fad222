"""Samples that outrun their robot's registration, held until it comes (pure: the time is passed in).

A robot is registered when the edge sees its liveliness tokens (or its explicit registration),
and its data comes on another path: the first samples of a robot that starts publishing at once
can reach the processing thread before its registration has instantiated its mappings. Dropping
them would lose a robot's first messages whenever discovery trails, as it does on a busy
machine. So a sample that no mapping takes *yet*, but that one of a robot type's mappings would
take once its robot registers (``MappingTable.awaits_robot``), waits here, in arrival order per
topic, for up to ``hold_ns`` (``registration.hold``). When the robot registers its samples are
made into records first, before any later sample of theirs. When the first sample of a topic has
waited ``hold_ns`` in vain, the topic's samples are given up and counted as unmapped, as they
were before, and its later ones are not held until the mappings change. At most
``max_samples`` samples and ``max_bytes`` of payload wait at once (a sample beyond either is
counted as unmapped at once): part of the edge's memory bound (``EdgeConfig.memory_bound``).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from fleetlink.roswire.subscriber import RosSample


@dataclass(slots=True)
class EarlyStats:
    """What became of the samples that came before their robot's registration."""

    held: int = 0
    """Samples that waited for their robot's registration."""
    released: int = 0
    """Of those, samples whose robot registered in time (made into records)."""
    expired: int = 0
    """Samples whose robot did not register within the hold (counted as unmapped)."""
    overflow: int = 0
    """Samples that found the hold full (counted as unmapped at once)."""


class EarlySamples:
    """The held samples, per topic in arrival order; not thread-safe (the processing thread's)."""

    def __init__(self, hold_ns: int, *, max_samples: int, max_bytes: int) -> None:
        self.hold_ns = hold_ns
        self.max_samples = max_samples
        self.max_bytes = max_bytes
        self._topics: dict[str, deque[tuple[int, RosSample]]] = {}
        self._given_up: set[str] = set()
        """Topics whose samples waited in vain: not held again until the mappings change (``retry``)."""
        self._count = 0
        self._bytes = 0
        self.stats = EarlyStats()

    def __len__(self) -> int:
        return self._count

    @property
    def bytes(self) -> int:
        """Payload bytes held now."""
        return self._bytes

    def holds(self, topic: str) -> bool:
        """Whether samples of ``topic`` wait (a later one must wait behind them)."""
        return topic in self._topics

    def waiting(self) -> dict[str, int]:
        """Topic -> samples waiting now (from any thread: a copy)."""
        return {topic: len(waiting) for topic, waiting in list(self._topics.items())}

    def topics(self) -> list[str]:
        """The topics with samples waiting."""
        return list(self._topics)

    def add(self, sample: RosSample, now_ns: int) -> bool:
        """Hold ``sample`` until ``now_ns + hold_ns``; False (not held) when the hold is off, full, or
        gave up on its topic."""
        if self.hold_ns <= 0 or sample.topic in self._given_up:
            return False
        size = len(sample.payload)
        if self._count >= self.max_samples or self._bytes + size > self.max_bytes:
            self.stats.overflow += 1
            return False
        waiting = self._topics.get(sample.topic)
        if waiting is None:
            waiting = self._topics[sample.topic] = deque()
        waiting.append((now_ns + self.hold_ns, sample))
        self._count += 1
        self._bytes += size
        self.stats.held += 1
        return True

    def release(self, topic: str) -> list[RosSample]:
        """Every sample of ``topic`` (its robot registered), in arrival order; none wait after."""
        waiting = self._topics.pop(topic, None)
        if waiting is None:
            return []
        out = [sample for _, sample in waiting]
        self._forget(out)
        self.stats.released += len(out)
        return out

    def expired(self, now_ns: int) -> list[RosSample]:
        """The samples of each topic whose oldest sample's hold ended by ``now_ns``, in arrival
        order: given up, with the topic (its later samples are not held)."""
        out: list[RosSample] = []
        for topic in list(self._topics):
            waiting = self._topics[topic]
            if waiting[0][0] > now_ns:
                continue
            self._given_up.add(topic)  # its robot did not come: the rest of the topic goes too
            out.extend(sample for _, sample in waiting)
            del self._topics[topic]
        self._forget(out)
        self.stats.expired += len(out)
        return out

    def retry(self) -> None:
        """The mappings changed: topics given up on may be taken, or awaited, again."""
        self._given_up.clear()

    def _forget(self, samples: list[RosSample]) -> None:
        self._count -= len(samples)
        self._bytes -= sum(len(s.payload) for s in samples)
