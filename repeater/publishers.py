"""One rmw_zenoh publisher per ROS topic, created when a command needs it and reused by later
commands on the same topic.

When no command is active on a topic any more, its publisher is *released*: a TRANSIENT_LOCAL
publisher is undeclared at once (its cache would otherwise serve the expired command to a late
joiner); a volatile one is kept for ``idle_ttl`` seconds, so a fleet that gets a command every
few seconds does not re-declare its publishers (and their liveliness tokens) each time.
"""

from __future__ import annotations

from dataclasses import dataclass

from fleetlink.roswire.errors import QosParseError
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.publisher import RosPublisher
from fleetlink.roswire.qos import DEFAULT, QoS

IDLE_TTL_S = 300.0


@dataclass(frozen=True)
class _Spec:
    typename: str
    qos: QoS


def parse_qos(text: str | None) -> QoS:
    """A command's compact QoS string (None: reliable, volatile, keep last 10)."""
    if not text:
        return DEFAULT
    return QoS.parse(text)


class Publishers:
    """Not thread-safe: the repeater calls it under its lock."""

    def __init__(self, node: RosNode, *, idle_ttl: float = IDLE_TTL_S) -> None:
        self._node = node
        self._idle_ttl = idle_ttl
        self._pubs: dict[str, tuple[_Spec, RosPublisher]] = {}
        self._idle: dict[str, float] = {}  # topic -> released at (seconds, caller's clock)

    def get(self, topic: str, typename: str, qos_text: str | None) -> RosPublisher:
        """The publisher for ``topic``; a different type or QoS replaces the old one.

        Raises ``QosParseError`` for a QoS string rmw_zenoh would not accept.
        """
        spec = _Spec(typename, parse_qos(qos_text))
        self._idle.pop(topic, None)
        known = self._pubs.get(topic)
        if known is not None:
            if known[0] == spec:
                return known[1]
            known[1].stop()
        publisher = self._node.create_publisher(topic, typename, spec.qos)
        self._pubs[topic] = (spec, publisher)
        return publisher

    def release(self, topic: str, now: float) -> None:
        """No command is active on ``topic`` any more."""
        known = self._pubs.get(topic)
        if known is None:
            return
        if known[0].qos.transient_local:
            self._stop(topic)
        else:
            self._idle.setdefault(topic, now)

    def sweep(self, now: float) -> None:
        """Undeclare the publishers idle for longer than ``idle_ttl``."""
        for topic in [t for t, since in self._idle.items() if now - since >= self._idle_ttl]:
            self._stop(topic)

    def topics(self) -> list[str]:
        """The topics that have a publisher now, idle ones included, sorted."""
        return sorted(self._pubs)

    def stop_all(self) -> None:
        """Undeclare every publisher, idle or not (the repeater is stopping)."""
        for topic in list(self._pubs):
            self._stop(topic)

    def _stop(self, topic: str) -> None:
        self._idle.pop(topic, None)
        known = self._pubs.pop(topic, None)
        if known is not None:
            known[1].stop()


__all__ = ["Publishers", "QosParseError", "parse_qos"]
