"""The per-sample attachment rmw_zenoh puts on every publication (rmw_zenoh.md §4).

* v2 (current, 33 bytes): ``int64 seq | int64 source_timestamp_ns | 0x10 | 16-byte gid``
* v1 (older, 77 bytes): the same values labelled with LEB128-prefixed strings
  ``"sequence_number"``, ``"source_timestamp"``, ``"source_gid"``.

Both are the zenoh-ext serialization of a tuple; this module builds and reads them with
``struct`` so the layout is explicit and checked byte by byte.
"""

from __future__ import annotations

import struct
from typing import Literal, NamedTuple

from fleetlink.roswire.errors import AttachmentError
from fleetlink.roswire.gid import GID_SIZE

AttachmentVersion = Literal[1, 2]

V2_SIZE = 33
V1_SIZE = 77
_V2 = struct.Struct("<qqB16s")
_LABEL_SEQ = b"\x0fsequence_number"
_LABEL_TS = b"\x10source_timestamp"
_LABEL_GID = b"\x0asource_gid"
_V1 = struct.Struct(f"<{len(_LABEL_SEQ)}sq{len(_LABEL_TS)}sq{len(_LABEL_GID)}sB16s")


class Attachment(NamedTuple):
    """One sample's attachment (a named tuple: one is made per received sample)."""

    seq: int
    source_ts_ns: int
    gid: bytes
    version: AttachmentVersion = 2

    def encode(self) -> bytes:
        """Serialize this attachment in its own layout version."""
        return encode(self.seq, self.source_ts_ns, self.gid, self.version)


def encode(seq: int, source_ts_ns: int, gid: bytes, version: AttachmentVersion = 2) -> bytes:
    """Serialize an attachment in the given layout version."""
    if len(gid) != GID_SIZE:
        raise AttachmentError(gid, f"a GID has {GID_SIZE} bytes, got {len(gid)}")
    try:
        if version == 2:
            return _V2.pack(seq, source_ts_ns, GID_SIZE, gid)
        if version == 1:
            return _V1.pack(_LABEL_SEQ, seq, _LABEL_TS, source_ts_ns, _LABEL_GID, GID_SIZE, gid)
    except struct.error as exc:
        raise AttachmentError(gid, f"value out of int64 range: {exc}") from None
    raise AttachmentError(b"", f"unknown attachment version {version!r}")


def detect_version(raw: bytes) -> AttachmentVersion | None:
    """2 for the 33-byte layout, 1 for the labelled 77-byte one, None for anything else."""
    if len(raw) == V2_SIZE:
        return 2
    if len(raw) == V1_SIZE and raw.startswith(_LABEL_SEQ):
        return 1
    return None


def decode(raw: bytes) -> Attachment:
    """Parse either layout; raise :class:`AttachmentError` (carrying the bytes) otherwise."""
    raw = bytes(raw)
    version = detect_version(raw)
    if version == 2:
        seq, ts, gid_len, gid = _V2.unpack(raw)
        if gid_len != GID_SIZE:
            raise AttachmentError(raw, f"GID length prefix is {gid_len}, expected {GID_SIZE}")
        return Attachment(seq, ts, gid, 2)
    if version == 1:
        _, seq, label_ts, ts, label_gid, gid_len, gid = _V1.unpack(raw)
        if label_ts != _LABEL_TS or label_gid != _LABEL_GID:
            raise AttachmentError(raw, "v1 labels are not 'source_timestamp' / 'source_gid'")
        if gid_len != GID_SIZE:
            raise AttachmentError(raw, f"GID length prefix is {gid_len}, expected {GID_SIZE}")
        return Attachment(seq, ts, gid, 1)
    if len(raw) == V1_SIZE:
        raise AttachmentError(raw, "77 bytes but no 'sequence_number' label")
    raise AttachmentError(raw, f"length {len(raw)} is neither {V2_SIZE} (v2) nor {V1_SIZE} (v1)")
