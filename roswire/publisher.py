"""``RosPublisher``: publish as an rmw_zenoh publisher does (rmw_zenoh.md §5).

Exact data key (type name and hash of the node's distro), an ``MP`` token with the real QoS,
CDR payload and an attachment on every sample (sequence from 1, send time, the GID derived from
the token). TRANSIENT_LOCAL topics go through an advanced publisher whose cache answers late
joiners, as rmw_zenoh's does.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import TYPE_CHECKING, Any, Literal

import zenoh
import zenoh.ext

from fleetlink.common.lifecycle import StartStop
from fleetlink.roswire.attachment import AttachmentVersion, encode
from fleetlink.roswire.errors import RoswireError
from fleetlink.roswire.gid import entity_gid
from fleetlink.roswire.names import data_key
from fleetlink.roswire.qos import DEFAULT, History, QoS, Reliability
from fleetlink.roswire.tokens import EntityKind

if TYPE_CHECKING:
    from fleetlink.roswire.node import RosNode

log = logging.getLogger(__name__)

Congestion = Literal["drop", "block"]
SPORADIC_HEARTBEAT_S = 0.5


class RosPublisher(StartStop):
    """One ROS 2 topic publisher as rmw_zenoh declares it: data key, ``MP`` token, CDR with an attachment."""

    def __init__(
        self,
        node: RosNode,
        topic: str,
        typename: str,
        qos: QoS = DEFAULT,
        *,
        type_hash: str | None = None,
        attachment_version: AttachmentVersion | None = None,
        congestion: Congestion | None = None,
    ) -> None:
        self.node = node
        self.topic = node.resolve(topic)
        self.typename = typename
        self.qos = qos
        self._type_hash = type_hash
        self.attachment_version: AttachmentVersion = attachment_version or node.attachment_version
        self.congestion = congestion
        self._publisher: zenoh.Publisher | zenoh.ext.AdvancedPublisher | None = None
        self._token: zenoh.LivelinessToken | None = None
        self._lock = threading.Lock()
        self.seq = 0
        self.key = ""
        self.token_key = ""
        self.gid = b""
        self.eid = -1

    @property
    def type_hash(self) -> str:
        """The type's hash as given, else computed once from the node's type store."""
        if self._type_hash is None:
            self._type_hash = self.node.type_hash(self.typename)
        return self._type_hash

    def _congestion(self) -> zenoh.CongestionControl:
        if self.congestion == "block" or (
            self.congestion is None
            and self.qos.reliability != Reliability.BEST_EFFORT
            and self.qos.history == History.KEEP_ALL
        ):
            return zenoh.CongestionControl.BLOCK
        return zenoh.CongestionControl.DROP

    def start(self) -> RosPublisher:
        """Declare the Zenoh publisher and the ``MP`` token; returns self.

        TRANSIENT_LOCAL topics get an advanced publisher whose cache (``depth`` samples) answers late
        joiners.
        """
        if self._publisher is not None:
            return self
        from fleetlink.roswire.node import next_entity_id

        session = self.node.session
        self.key = data_key(self.node.domain_id, self.topic, self.typename, self.type_hash)
        self.eid = next_entity_id()
        self.token_key = self.node.endpoint_token(
            EntityKind.PUBLISHER,
            self.topic,
            self.typename,
            type_hash=self.type_hash,
            qos=self.qos,
            eid=self.eid,
        )
        self.gid = entity_gid(self.token_key)
        reliability = zenoh.Reliability.BEST_EFFORT if self.qos.best_effort else zenoh.Reliability.RELIABLE
        if self.qos.transient_local:
            miss = None
            if not self.qos.best_effort:
                miss = zenoh.ext.MissDetectionConfig(heartbeat=None, sporadic_heartbeat=SPORADIC_HEARTBEAT_S)
            self._publisher = zenoh.ext.declare_advanced_publisher(
                session,
                self.key,
                congestion_control=self._congestion(),
                reliability=reliability,
                cache=zenoh.ext.CacheConfig(max_samples=max(self.qos.depth, 1)),
                sample_miss_detection=miss,
                publisher_detection=True,
            )
        else:
            self._publisher = session.declare_publisher(
                self.key, congestion_control=self._congestion(), reliability=reliability
            )
        self._token = session.liveliness().declare_token(self.token_key)
        self.node.adopt(self)
        log.debug("publisher started key=%s token=%s", self.key, self.token_key)
        return self

    def stop(self) -> None:
        """Undeclare the token and the publisher, and detach from the node."""
        if self._token is not None:
            self._token.undeclare()
            self._token = None
        if self._publisher is not None:
            publisher: Any = self._publisher  # AdvancedPublisher.undeclare is untyped in the stubs
            publisher.undeclare()
            self._publisher = None
        self.node.forget(self)

    def publish_cdr(self, payload: bytes, *, source_ts_ns: int | None = None, block: bool = False) -> int:
        """Put one CDR-encoded message; returns its sequence number. ``block``: this one sample
        waits for room on the way instead of being dropped, whatever the publisher's congestion
        control (after it, a sample dropped before shows as a gap in the sequence numbers)."""
        publisher = self._publisher
        if publisher is None:
            raise RoswireError(f"publisher on {self.topic} is not started")
        with self._lock:
            self.seq += 1
            seq = self.seq
            stamp = time.time_ns() if source_ts_ns is None else source_ts_ns
            attachment = encode(seq, stamp, self.gid, self.attachment_version)
            if block:  # the same key, priority and order as the publisher's own samples
                self.node.session.put(
                    self.key, payload, attachment=attachment, congestion_control=zenoh.CongestionControl.BLOCK
                )
            else:
                publisher.put(payload, attachment=attachment)
        return seq

    def publish(self, message: object) -> int:
        """Serialize ``message`` (a rosbags object of this publisher's type) and put it."""
        ts = self.node.typestore
        if ts is None:
            raise RoswireError(f"publisher on {self.topic}: the node has no type store to serialize with")
        return self.publish_cdr(bytes(ts.serialize_cdr(message, self.typename)))

    def has_subscribers(self, timeout: float = 1.0) -> bool:
        """Whether a subscriber is there: zenoh's matching status where available, otherwise
        (advanced publishers) whether any ``MS`` token for this topic answers a liveliness query."""
        matching = self.matching
        if matching is not None:
            return matching
        return self.node.announced(EntityKind.SUBSCRIPTION, self.topic, timeout)

    @property
    def matching(self) -> bool | None:
        """Whether any subscriber matches (None where zenoh cannot tell: advanced publishers)."""
        publisher = self._publisher
        if isinstance(publisher, zenoh.Publisher):
            # the stubs say bool; zenoh 1.10 returns a MatchingStatus with a .matching flag
            status: Any = publisher.matching_status
            return bool(getattr(status, "matching", status))
        return None
