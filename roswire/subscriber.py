"""``RosSubscriber``: receive a ROS topic from rmw_zenoh publishers (rmw_zenoh.md §4, §5).

Subscribes to ``<domain>/<topic>/<dds type or *>/<hash or *>``, reads both attachment layouts,
tracks sequence numbers per publisher GID and hands each good sample to the callback as a
:class:`RosSample`. Bad traffic is counted and reported (``on_error``), never raised into zenoh:
samples without or with a broken attachment, keys that are not data keys, payloads without a
CDR header or that do not decode. TRANSIENT_LOCAL subscriptions fetch the publishers' caches.
"""

from __future__ import annotations

import logging
import struct
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from types import TracebackType
from typing import TYPE_CHECKING, Any

import zenoh
import zenoh.ext
from rosbags.serde import SerdeError

from roswire import cdr
from roswire.attachment import decode as decode_attachment
from roswire.errors import AttachmentError, KeyParseError, PayloadError, RoswireError
from roswire.names import DataKey, data_key_expr, parse_data_key
from roswire.qos import DEFAULT, QoS
from roswire.sequence import SeqStatus, SequenceTracker
from roswire.tokens import EntityKind, endpoint_token

if TYPE_CHECKING:
    from roswire.node import RosNode

log = logging.getLogger(__name__)

_KEY_CACHE_SIZE = 1024  # parsed data keys remembered per subscriber (one per publisher type/hash)

# What rosbags raises for bytes that are not a message of the type (or an unknown type).
_DECODE_ERRORS = (SerdeError, KeyError, ValueError, IndexError, struct.error, UnicodeDecodeError)


@dataclass(frozen=True)
class RosSample:
    topic: str
    typename: str
    type_hash: str
    payload: bytes
    seq: int | None
    source_ts_ns: int | None
    gid: bytes | None
    key: str
    received_ns: int
    attachment_version: int | None = None
    message: Any = None
    """The decoded message when the subscriber decodes (``decode=True``), else None."""


@dataclass
class SubscriberStats:
    received: int = 0
    delivered: int = 0
    no_attachment: int = 0
    bad_attachment: int = 0
    bad_key: int = 0
    bad_payload: int = 0
    gaps: int = 0
    missing: int = 0
    duplicates: int = 0
    callback_errors: int = 0
    attachment_versions: Counter[int] = field(default_factory=Counter)

    @property
    def rejected(self) -> int:
        return self.no_attachment + self.bad_attachment + self.bad_key + self.bad_payload


ErrorHandler = Callable[[RoswireError], object]


class RosSubscriber:
    def __init__(
        self,
        node: RosNode,
        topic: str,
        typename: str | None,
        callback: Callable[[RosSample], object],
        qos: QoS = DEFAULT,
        *,
        type_hash: str | None = None,
        accept_missing_attachment: bool = False,
        decode: bool = False,
        on_error: ErrorHandler | None = None,
        declare_token: bool = True,
    ) -> None:
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
        self.stats = SubscriberStats()
        self.sequences = SequenceTracker()
        self._sub: zenoh.Subscriber[None] | zenoh.ext.AdvancedSubscriber[None] | None = None
        self._token: zenoh.LivelinessToken | None = None
        self._lock = threading.Lock()
        self._warned: set[str] = set()
        self._keys: dict[str, DataKey] = {}
        self.key_expr = ""
        self.token_key = ""

    def start(self) -> RosSubscriber:
        if self._sub is not None:
            return self
        if self.decode and self.node.typestore is None:
            raise RoswireError(f"subscriber on {self.topic}: decode=True needs a node with a type store")
        session = self.node.session
        self.key_expr = data_key_expr(self.node.domain_id, self.topic, self.typename, self.type_hash)
        if self.qos.transient_local:
            depth = max(self.qos.depth, 1)
            recovery = None if self.qos.best_effort else zenoh.ext.RecoveryConfig(
                periodic_queries=None, heartbeat=True)
            self._sub = zenoh.ext.declare_advanced_subscriber(
                session, self.key_expr, self._on_sample,
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=depth),
                recovery=recovery, subscriber_detection=True,
            )
        else:
            self._sub = session.declare_subscriber(self.key_expr, self._on_sample)
        token_hash = self.type_hash
        if self.declare_token and self.typename is not None and token_hash is None and self.node.typestore:
            token_hash = self.node.type_hash(self.typename)
        if self.declare_token and self.typename is not None and token_hash is not None:
            from roswire.node import next_entity_id

            self.token_key = endpoint_token(
                domain=self.node.domain_id, zid=self.node.zid, nid=self.node.nid, eid=next_entity_id(),
                kind=EntityKind.SUBSCRIPTION, namespace=self.node.namespace, node_name=self.node.name,
                topic=self.topic, typename=self.typename, type_hash=token_hash, qos=self.qos,
                enclave=self.node.enclave,
            )
            self._token = session.liveliness().declare_token(self.token_key)
        self.node.adopt(self)
        log.debug("subscriber started key_expr=%s token=%s", self.key_expr, self.token_key or "-")
        return self

    def stop(self) -> None:
        if self._token is not None:
            self._token.undeclare()
            self._token = None
        if self._sub is not None:
            sub: Any = self._sub  # AdvancedSubscriber.undeclare is untyped in the stubs
            sub.undeclare()
            self._sub = None
        self.node.forget(self)

    def __enter__(self) -> RosSubscriber:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    # --- receive path (runs on a zenoh thread: never raises) --------------------------------

    def _on_sample(self, sample: zenoh.Sample) -> None:
        received_ns = time.time_ns()
        key = str(sample.key_expr)
        try:
            with self._lock:
                out = self._accept(sample, key, received_ns)
        except RoswireError as exc:
            self._report(exc)
            return
        if out is None:
            return
        try:
            self.callback(out)
        except Exception as exc:  # noqa: BLE001 - any callback failure is counted; the subscription lives on
            self.stats.callback_errors += 1
            self._warn_once("callback", "subscriber callback failed key=%s: %r", key, exc)

    def _accept(self, sample: zenoh.Sample, key: str, received_ns: int) -> RosSample | None:
        stats = self.stats
        stats.received += 1
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
        raw_att = sample.attachment
        seq = ts = gid = version = None
        if raw_att is None:
            stats.no_attachment += 1
            if not self.accept_missing_attachment:
                raise PayloadError(key, parsed.ros_type, payload, "sample has no rmw_zenoh attachment")
        else:
            try:
                att = decode_attachment(raw_att.to_bytes())
            except AttachmentError:
                stats.bad_attachment += 1
                raise
            seq, ts, gid, version = att.seq, att.source_ts_ns, att.gid, att.version
            stats.attachment_versions[version] += 1
        problem = cdr.header_problem(payload)
        if problem is not None:
            stats.bad_payload += 1
            raise PayloadError(key, parsed.ros_type, payload, problem)
        message = None
        if self.decode:
            message = self._decode(key, parsed.ros_type, payload)
        if gid is not None and seq is not None:
            result = self.sequences.observe(gid, seq)
            if result.status is SeqStatus.GAP:
                stats.gaps += 1
                stats.missing += result.missing
            elif result.status is SeqStatus.DUPLICATE:
                stats.duplicates += 1
        stats.delivered += 1
        return RosSample(
            parsed.topic, parsed.ros_type, parsed.type_hash, payload, seq, ts, gid, key, received_ns,
            version, message,
        )

    def _decode(self, key: str, typename: str, payload: bytes) -> Any:
        ts = self.node.typestore
        if ts is None:
            raise PayloadError(key, typename, payload, "no type store")
        try:
            return ts.deserialize_cdr(payload, typename)
        except _DECODE_ERRORS as exc:
            self.stats.bad_payload += 1
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
