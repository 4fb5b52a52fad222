"""Whether a received sample is an rmw_zenoh message, and what it says (rmw_zenoh.md §4, §5). Pure.

``SampleAcceptor.accept(key, payload, attachment, received_ns)`` does what an rmw_zenoh
subscriber does with each sample: parse the data key (remembered per key), read the attachment
(both layouts), check the CDR encapsulation header, optionally decode, and follow each
publisher's sequence numbers. The result is a :class:`RosSample`; anything else raises the
matching ``RoswireError`` (``KeyParseError``, ``AttachmentError``, ``PayloadError``) carrying
the key and the raw bytes, and is counted in :class:`SubscriberStats`. Not thread-safe: one
acceptor per subscription, used by one thread at a time.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from fleetlink.roswire import cdr
from fleetlink.roswire.attachment import decode as decode_attachment
from fleetlink.roswire.errors import AttachmentError, KeyParseError, PayloadError
from fleetlink.roswire.names import DataKey, parse_data_key
from fleetlink.roswire.sequence import SeqStatus, SequenceTracker

_KEY_CACHE_SIZE = 1024  # parsed data keys remembered per subscription (one per publisher type/hash)


class RosSample(NamedTuple):
    """One accepted sample (a named tuple: thousands are made per second on a busy topic)."""

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
    """What one subscription received: delivered and rejected samples, sequence gaps, callback failures."""

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
        """Samples turned away: without or with a bad attachment, with a bad key or a bad payload."""
        return self.no_attachment + self.bad_attachment + self.bad_key + self.bad_payload


Decoder = Callable[[str, str, bytes], Any]
"""``(key, typename, payload) -> message``; raises ``PayloadError`` when it does not decode."""


class SampleAcceptor:
    """Checks samples of one subscription as an rmw_zenoh subscriber does and counts the outcome."""

    def __init__(
        self,
        *,
        accept_missing_attachment: bool = False,
        decoder: Decoder | None = None,
        track_sequences: bool = True,
    ) -> None:
        self.accept_missing_attachment = accept_missing_attachment
        self.decoder = decoder
        self.track_sequences = track_sequences
        """False when the samples' sequence numbers were already followed (the edge's data plane)."""
        self.stats = SubscriberStats()
        self.sequences = SequenceTracker()
        self._keys: dict[str, DataKey] = {}

    def accept(self, key: str, payload: bytes, attachment: bytes | None, received_ns: int) -> RosSample:
        """The sample as a ``RosSample``, or the ``RoswireError`` saying why it is not one."""
        stats = self.stats
        stats.received += 1
        parsed = self._keys.get(key) or self._data_key(key)
        seq = ts = gid = version = None
        if attachment is None:
            stats.no_attachment += 1
            if not self.accept_missing_attachment:
                raise PayloadError(key, parsed.ros_type, payload, "sample has no rmw_zenoh attachment")
        else:
            try:
                att = decode_attachment(attachment)
            except AttachmentError as exc:
                stats.bad_attachment += 1
                raise AttachmentError(exc.raw, exc.reason, key=key, payload=payload) from None
            seq, ts, gid, version = att.seq, att.source_ts_ns, att.gid, att.version
            stats.attachment_versions[version] += 1
        problem = cdr.header_problem(payload)
        if problem is not None:
            stats.bad_payload += 1
            raise PayloadError(key, parsed.ros_type, payload, problem)
        message = None
        if self.decoder is not None:
            try:
                message = self.decoder(key, parsed.ros_type, payload)
            except PayloadError:
                stats.bad_payload += 1
                raise
        if gid is not None and seq is not None and self.track_sequences:
            self._observe(gid, seq)
        stats.delivered += 1
        return RosSample(
            parsed.topic,
            parsed.ros_type,
            parsed.type_hash,
            payload,
            seq,
            ts,
            gid,
            key,
            received_ns,
            version,
            message,
        )

    def _data_key(self, key: str) -> DataKey:
        try:
            parsed = parse_data_key(key)
        except KeyParseError:
            self.stats.bad_key += 1
            raise
        if len(self._keys) >= _KEY_CACHE_SIZE:
            self._keys.clear()
        self._keys[key] = parsed
        return parsed

    def _observe(self, gid: bytes, seq: int) -> None:
        result = self.sequences.observe(gid, seq)
        if result.status is SeqStatus.NEXT:
            return
        if result.status is SeqStatus.GAP:
            self.stats.gaps += 1
            self.stats.missing += result.missing
        elif result.status is SeqStatus.DUPLICATE:
            self.stats.duplicates += 1
