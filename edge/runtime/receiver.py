"""One mapped topic's subscription, drained off the Zenoh threads.

A Python callback on a Zenoh subscriber runs under the GIL; on a busy edge (the processing
thread decoding and encoding, other subscriptions) the network thread then waits for the GIL,
the router's queue towards the edge fills and samples are lost before fleetlink ever sees them.
So the subscription hands its samples to a **Rust-side ring channel** (``RingChannel``, no GIL,
never blocks the network thread) and a small thread per topic drains it: it checks each sample
the way an rmw_zenoh subscriber does (data key, attachment, CDR header, sequence per publisher)
and passes it on. If the ring overflows (the edge far behind), the oldest samples are replaced;
the publishers' sequence numbers reveal every such loss as a gap (``stats.missing``).

An ``MS`` liveliness token is declared like an rmw_zenoh subscription's, so the edge shows up
in the ROS graph. The type hash is not part of the key expression (``*``): a publisher built
against another definition of the type is still received.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import zenoh

from roswire import cdr
from roswire.attachment import decode as decode_attachment
from roswire.errors import AttachmentError, KeyParseError, PayloadError, RoswireError
from roswire.names import DataKey, data_key_expr, parse_data_key
from roswire.node import RosNode, next_entity_id
from roswire.qos import DEFAULT
from roswire.sequence import SeqStatus, SequenceTracker
from roswire.subscriber import RosSample, SubscriberStats
from roswire.tokens import EntityKind, endpoint_token

log = logging.getLogger(__name__)

_KEY_CACHE_SIZE = 1024

Sink = Callable[[RosSample], object]
ErrorSink = Callable[[RoswireError], object]


class TopicReceiver:
    """Receives one topic (any hash; one type, or any type when ``typename`` is None)."""

    def __init__(
        self,
        node: RosNode,
        topic: str,
        typename: str | None,
        sink: Sink,
        on_error: ErrorSink,
        *,
        capacity: int = 65536,
        declare_token: bool = True,
    ) -> None:
        self.node = node
        self.topic = node.resolve(topic)
        self.typename = typename
        self.sink = sink
        self.on_error = on_error
        self.capacity = capacity
        self.declare_token = declare_token
        self.stats = SubscriberStats()
        self.sequences = SequenceTracker()
        self.key_expr = ""
        self.token_key = ""
        self._sub: zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]] | None = None
        self._token: zenoh.LivelinessToken | None = None
        self._thread: threading.Thread | None = None
        self._keys: dict[str, DataKey] = {}
        self._warned: set[str] = set()

    def start(self) -> TopicReceiver:
        if self._sub is not None:
            return self
        session = self.node.session
        self.key_expr = data_key_expr(self.node.domain_id, self.topic, self.typename, None)
        self._sub = session.declare_subscriber(self.key_expr, zenoh.handlers.RingChannel(self.capacity))
        self._thread = threading.Thread(target=self._drain, args=(self._sub,), daemon=True,
                                        name=f"recv{self.topic}")
        self._thread.start()
        if self.declare_token and self.typename is not None:
            self.token_key = endpoint_token(
                domain=self.node.domain_id, zid=self.node.zid, nid=self.node.nid, eid=next_entity_id(),
                kind=EntityKind.SUBSCRIPTION, namespace=self.node.namespace, node_name=self.node.name,
                topic=self.topic, typename=self.typename, type_hash=self.node.type_hash(self.typename),
                qos=DEFAULT, enclave=self.node.enclave,
            )
            self._token = session.liveliness().declare_token(self.token_key)
        return self

    def stop(self) -> None:
        """Undeclare; samples still in the ring are handed on before the thread ends."""
        if self._token is not None:
            try:
                self._token.undeclare()
            except zenoh.ZError as exc:
                log.debug("token undeclare on %s: %s", self.topic, exc)
            self._token = None
        if self._sub is not None:
            try:
                self._sub.undeclare()
            except zenoh.ZError as exc:
                log.debug("subscriber undeclare on %s: %s", self.topic, exc)
            self._sub = None
        if self._thread is not None:
            self._thread.join(5)
            self._thread = None

    # -- the drain thread ------------------------------------------------------------------------
    def _drain(self, sub: zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]]) -> None:
        ring = sub.handler
        while True:
            try:
                sample = ring.recv()
            except zenoh.ZError:  # undeclared and empty
                return
            try:
                accepted = self._accept(sample)
            except RoswireError as exc:
                self._report(exc)
                continue
            try:
                self.sink(accepted)
            except Exception as exc:  # noqa: BLE001 - a failing sink must not end the subscription
                self.stats.callback_errors += 1
                self._warn("sink", "receiver on %s: handing a sample on failed: %r", self.topic, exc)

    def _accept(self, sample: zenoh.Sample) -> RosSample:
        received_ns = time.time_ns()
        stats = self.stats
        stats.received += 1
        key = str(sample.key_expr)
        parsed = self._keys.get(key)
        if parsed is None:
            try:
                parsed = parse_data_key(key)
            except KeyParseError:
                stats.bad_key += 1
                raise
            if len(self._keys) >= _KEY_CACHE_SIZE:
                self._keys.clear()
            self._keys[key] = parsed
        payload = sample.payload.to_bytes()
        raw_attachment = sample.attachment
        if raw_attachment is None:
            stats.no_attachment += 1
            raise PayloadError(key, parsed.ros_type, payload, "sample has no rmw_zenoh attachment")
        try:
            attachment = decode_attachment(raw_attachment.to_bytes())
        except AttachmentError as exc:
            stats.bad_attachment += 1
            raise PayloadError(key, parsed.ros_type, payload, f"broken attachment: {exc.reason}") from None
        stats.attachment_versions[attachment.version] += 1
        problem = cdr.header_problem(payload)
        if problem is not None:
            stats.bad_payload += 1
            raise PayloadError(key, parsed.ros_type, payload, problem)
        result = self.sequences.observe(attachment.gid, attachment.seq)
        if result.status is SeqStatus.GAP:
            stats.gaps += 1
            stats.missing += result.missing
        elif result.status is SeqStatus.DUPLICATE:
            stats.duplicates += 1
        stats.delivered += 1
        return RosSample(parsed.topic, parsed.ros_type, parsed.type_hash, payload, attachment.seq,
                         attachment.source_ts_ns, attachment.gid, key, received_ns, attachment.version)

    def _report(self, exc: RoswireError) -> None:
        self._warn(type(exc).__name__, "receiver on %s refused a sample: %s", self.topic, exc)
        try:
            self.on_error(exc)
        except Exception as cb_exc:  # noqa: BLE001 - the reporter must not break the receive path
            self._warn("on_error", "receiver on %s: error handler failed: %r", self.topic, cb_exc)

    def _warn(self, what: str, msg: str, *args: object) -> None:
        if what in self._warned:
            log.debug(msg, *args)
            return
        self._warned.add(what)
        log.warning(msg + " (further ones are counted, logged at debug)", *args)
