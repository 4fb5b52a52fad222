"""Subscribers in the ROS graph: how many each topic has (a publish with one present is a
delivery) and which topics one joined since the last look (a late joiner gets the active
command at once)."""

from __future__ import annotations

import threading
from collections import Counter

from fleetlink.roswire.graph import EventKind, GraphEvent
from fleetlink.roswire.tokens import EndpointInfo, EntityKind


class SubscriberWatch:
    """Fed by a ``GraphWatcher``; ``poke`` wakes the publish loop when a subscriber comes or goes."""

    def __init__(self, poke: threading.Event) -> None:
        self._poke = poke
        self._lock = threading.Lock()
        self._subscribers: Counter[str] = Counter()
        self._joined: set[str] = set()

    def on_graph(self, event: GraphEvent) -> None:
        """Count a subscription that appeared or went away, and wake the publish loop."""
        # runs on a zenoh thread under the watcher's lock: never take the repeater's lock here
        entity = event.entity
        if not isinstance(entity, EndpointInfo) or entity.kind is not EntityKind.SUBSCRIPTION:
            return
        with self._lock:
            if event.kind is EventKind.APPEARED:
                self._subscribers[entity.topic] += 1
                self._joined.add(entity.topic)
            else:
                self._subscribers[entity.topic] -= 1
                if self._subscribers[entity.topic] <= 0:
                    del self._subscribers[entity.topic]
        self._poke.set()

    def count(self, topic: str) -> int:
        """How many subscribers the ROS graph shows on ``topic`` now."""
        with self._lock:
            return self._subscribers.get(topic, 0)

    def take_joined(self) -> set[str]:
        """The topics a subscriber appeared on since the last call."""
        with self._lock:
            joined, self._joined = self._joined, set()
        return joined
