"""One rmw_zenoh publisher per ROS topic, created when a command needs it, reused by later
commands on the same topic, and undeclared when no command is active there any more (so no
publisher, no ``MP`` token and no cache outlives the lease)."""

from __future__ import annotations

from dataclasses import dataclass

from roswire.errors import QosParseError
from roswire.node import RosNode
from roswire.publisher import RosPublisher
from roswire.qos import DEFAULT, QoS


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

    def __init__(self, node: RosNode) -> None:
        self._node = node
        self._pubs: dict[str, tuple[_Spec, RosPublisher]] = {}

    def get(self, topic: str, typename: str, qos_text: str | None) -> RosPublisher:
        """The publisher for ``topic``; a different type or QoS replaces the old one.

        Raises ``QosParseError`` for a QoS string rmw_zenoh would not accept.
        """
        spec = _Spec(typename, parse_qos(qos_text))
        known = self._pubs.get(topic)
        if known is not None:
            if known[0] == spec:
                return known[1]
            known[1].stop()
        publisher = self._node.create_publisher(topic, typename, spec.qos)
        self._pubs[topic] = (spec, publisher)
        return publisher

    def release(self, topic: str) -> None:
        known = self._pubs.pop(topic, None)
        if known is not None:
            known[1].stop()

    def topics(self) -> list[str]:
        return sorted(self._pubs)

    def stop_all(self) -> None:
        for topic in list(self._pubs):
            self.release(topic)


__all__ = ["Publishers", "QosParseError", "parse_qos"]
