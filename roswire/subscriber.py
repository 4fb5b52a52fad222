"""``RosSubscriber``: receive a ROS topic from rmw_zenoh publishers (rmw_zenoh.md §4, §5).

Subscribes to ``<domain>/<topic>/<dds type or *>/<hash or *>``, checks every sample like an
rmw_zenoh subscriber (``roswire.acceptance``: both attachment layouts, CDR header, sequence
numbers per publisher GID) and hands each good one to the callback as a :class:`RosSample`. Bad
traffic is counted and reported (``on_error``), never raised into zenoh: samples without or with
a broken attachment, keys that are not data keys, payloads without a CDR header or that do not
decode. TRANSIENT_LOCAL subscriptions fetch the publishers' caches.

Two ways to receive:

* default: the callback runs on a Zenoh thread, for light traffic (discovery, commands);
* ``ring=N``: samples go into a Rust-side ring channel of ``N`` samples and a thread of the
  subscriber's own drains it and runs the callback (or, with ``on_samples``, hands over the
  samples of each burst together: one call, one lock on the receiving side, per burst). Use
  it for busy topics: a Python callback on a Zenoh thread waits for the GIL while the process
  is busy, which stalls Zenoh's network thread until the router's queue towards this process
  overflows and samples are lost before they are seen (three robots replaying the Husky IMU at
  full speed through a router: a callback received 7,169 + 6,687 + 847 of 3 x 11,865 samples,
  the ring all 35,595). A ring that overflows while the process is far behind drops its
  oldest samples; the publishers' sequence numbers show each such loss as a gap
  (``stats.missing``).
"""

from __future__ import annotations

import logging
import struct
import threading
import time
from collections.abc import Callable
from types import TracebackType
from typing import TYPE_CHECKING, Any

import zenoh
import zenoh.ext
from rosbags.serde import SerdeError

from fleetlink.roswire.acceptance import RosSample, SampleAcceptor, SubscriberStats
from fleetlink.roswire.errors import PayloadError, RoswireError
from fleetlink.roswire.names import data_key_expr
from fleetlink.roswire.qos import DEFAULT, QoS
from fleetlink.roswire.sequence import SequenceTracker
from fleetlink.roswire.session import undeclare
from fleetlink.roswire.tokens import EntityKind

if TYPE_CHECKING:
    from fleetlink.roswire.node import RosNode

__all__ = ["ErrorHandler", "RosSample", "RosSubscriber", "SubscriberStats"]

log = logging.getLogger(__name__)

_BURST = 256
"""With ``on_samples``: samples handed over at most this many at a time."""

# What rosbags raises for bytes that are not a message of the type (or an unknown type).
_DECODE_ERRORS = (SerdeError, KeyError, ValueError, IndexError, struct.error, UnicodeDecodeError)


ErrorHandler = Callable[[RoswireError], object]


class RosSubscriber:
    """One ROS 2 topic subscription: checks each sample as rmw_zenoh does and hands the good ones on."""

    def __init__(
        self,
        node: RosNode,
        topic: str,
        typename: str | None,
        callback: Callable[[RosSample], object] | None,
        qos: QoS = DEFAULT,
        *,
        type_hash: str | None = None,
        accept_missing_attachment: bool = False,
        decode: bool = False,
        on_error: ErrorHandler | None = None,
        declare_token: bool = True,
        ring: int | None = None,
        on_samples: Callable[[list[RosSample]], object] | None = None,
    ) -> None:
        if ring is not None and ring < 1:
            raise RoswireError(f"subscriber on {topic}: a ring holds at least one sample, got {ring}")
        if (callback is None) == (on_samples is None) or (on_samples is not None and ring is None):
            raise RoswireError(f"subscriber on {topic}: give a callback, or on_samples with a ring")
        self.node = node
        self.topic = node.resolve(topic)
        self.typename = typename
        self.callback = callback
        self.qos = qos
        self.type_hash = type_hash
        self.accept_missing_attachment = accept_missing_attachment
        self.decode = decode
        self.on_error = on_error
        self.declare_token = declare_token
        self.ring = ring
        self.on_samples = on_samples
        self._acceptor = SampleAcceptor(
            accept_missing_attachment=accept_missing_attachment, decoder=self._decode if decode else None
        )
        self._sub: Any = None  # a (possibly advanced) subscriber, with a callback or a ring
        self._thread: threading.Thread | None = None
        self._token: zenoh.LivelinessToken | None = None
        self._lock = threading.Lock()
        self._warned: set[str] = set()
        self.key_expr = ""
        self.token_key = ""

    def start(self) -> RosSubscriber:
        """Declare the Zenoh subscriber (with the ring's drain thread) and the ``MS`` token; returns self.

        The token needs ``declare_token``, a type name, and a type hash given or computable.
        """
        if self._sub is not None:
            return self
        if self.decode and self.node.typestore is None:
            raise RoswireError(f"subscriber on {self.topic}: decode=True needs a node with a type store")
        session = self.node.session
        self.key_expr = data_key_expr(self.node.domain_id, self.topic, self.typename, self.type_hash)
        handler: Any = self._on_sample if self.ring is None else zenoh.handlers.RingChannel(self.ring)
        if self.qos.transient_local:
            depth = max(self.qos.depth, 1)
            recovery = (
                None
                if self.qos.best_effort
                else zenoh.ext.RecoveryConfig(periodic_queries=None, heartbeat=True)
            )
            self._sub = zenoh.ext.declare_advanced_subscriber(
                session,
                self.key_expr,
                handler,
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=depth),
                recovery=recovery,
                subscriber_detection=True,
            )
        else:
            self._sub = session.declare_subscriber(self.key_expr, handler)
        if self.ring is not None:
            self._thread = threading.Thread(
                target=self._drain, args=(self._sub.handler,), daemon=True, name=f"recv{self.topic}"
            )
            self._thread.start()
        token_hash = self.type_hash
        if self.declare_token and self.typename is not None and token_hash is None and self.node.typestore:
            token_hash = self.node.type_hash(self.typename)
        if self.declare_token and self.typename is not None and token_hash is not None:
            self.token_key = self.node.endpoint_token(
                EntityKind.SUBSCRIPTION, self.topic, self.typename, type_hash=token_hash, qos=self.qos
            )
            self._token = session.liveliness().declare_token(self.token_key)
        self.node.adopt(self)
        log.debug("subscriber started key_expr=%s token=%s", self.key_expr, self.token_key or "-")
        return self

    def stop(self) -> None:
        """Undeclare; with a ring, the samples still in it are handed on before its thread ends.
        (A session already closed has undeclared everything: that is not an error here.)"""
        if self._token is not None:
            undeclare(self._token, log, "token", self.topic)
            self._token = None
        if self._sub is not None:
            undeclare(self._sub, log, "subscriber", self.topic)
            self._sub = None
        if self._thread is not None:
            self._thread.join(5)
            self._thread = None
        self.node.forget(self)

    @property
    def stats(self) -> SubscriberStats:
        """Counts of the samples received, delivered and rejected so far."""
        return self._acceptor.stats

    @property
    def sequences(self) -> SequenceTracker:
        """The last sequence number seen from each publisher GID."""
        return self._acceptor.sequences

    def __enter__(self) -> RosSubscriber:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    # --- receive path (never raises into zenoh) ---------------------------------------------

    def _drain(self, ring: zenoh.handlers.Handler[zenoh.Sample]) -> None:
        """The ring's own thread: until the subscriber is undeclared and the ring is empty.

        ``recv`` waits without the GIL, and so must take it back for every sample it returns:
        with other Python threads busy that costs some 25 us a sample on the test machine. So
        only the first sample of a burst is waited for; the rest are taken with ``try_recv``,
        which keeps the GIL (0.3 us a sample). One thread: the acceptor needs no lock here.
        """
        accept, try_recv = self._acceptor.accept, ring.try_recv
        time_ns = time.time_ns
        callback = self.callback
        burst: list[RosSample] = []
        while True:
            try:
                sample: zenoh.Sample | None = ring.recv()
                while sample is not None:
                    raw_attachment = sample.attachment
                    try:
                        out = accept(
                            str(sample.key_expr),
                            sample.payload.to_bytes(),
                            None if raw_attachment is None else raw_attachment.to_bytes(),
                            time_ns(),
                        )
                    except RoswireError as exc:
                        self._report(exc)
                    else:
                        if callback is None:
                            burst.append(out)
                            if len(burst) >= _BURST:
                                self._hand_over(burst)
                                burst = []
                        else:
                            try:
                                callback(out)
                            except Exception as exc:  # noqa: BLE001 - counted; the subscription lives on
                                self._callback_failed(out.key, exc)
                    sample = try_recv()
            except zenoh.ZError:  # undeclared, and nothing left
                return
            finally:
                if burst:
                    self._hand_over(burst)
                    burst = []

    def _hand_over(self, burst: list[RosSample]) -> None:
        on_samples = self.on_samples
        if on_samples is None:
            return
        try:
            on_samples(burst)
        except Exception as exc:  # noqa: BLE001 - counted; the subscription lives on
            self._callback_failed(burst[0].key, exc)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        """The callback on Zenoh's threads (without a ring)."""
        received_ns = time.time_ns()
        key = str(sample.key_expr)
        raw_attachment = sample.attachment
        attachment = None if raw_attachment is None else raw_attachment.to_bytes()
        try:
            with self._lock:
                out = self._acceptor.accept(key, sample.payload.to_bytes(), attachment, received_ns)
        except RoswireError as exc:
            self._report(exc)
            return
        try:
            if self.callback is not None:
                self.callback(out)
        except Exception as exc:  # noqa: BLE001 - any callback failure is counted; the subscription lives on
            self._callback_failed(key, exc)

    def _callback_failed(self, key: str, exc: Exception) -> None:
        self.stats.callback_errors += 1
        self._warn_once("callback", "subscriber callback failed key=%s: %r", key, exc)

    def _decode(self, key: str, typename: str, payload: bytes) -> Any:
        ts = self.node.typestore
        if ts is None:
            raise PayloadError(key, typename, payload, "no type store")
        try:
            return ts.deserialize_cdr(payload, typename)
        except _DECODE_ERRORS as exc:
            raise PayloadError(key, typename, payload, f"does not decode: {exc!r}") from None

    def _report(self, exc: RoswireError) -> None:
        self._warn_once(type(exc).__name__, "subscriber on %s rejected a sample: %s", self.topic, exc)
        if self.on_error is not None:
            try:
                self.on_error(exc)
            except Exception as cb_exc:  # noqa: BLE001 - the reporter must not break the receive path
                self._warn_once("on_error", "on_error handler failed: %r", cb_exc)

    def _warn_once(self, what: str, msg: str, *args: object) -> None:
        if what in self._warned:
            log.debug(msg, *args)
            return
        self._warned.add(what)
        log.warning(msg + " (further ones are counted in stats, logged at debug)", *args)
