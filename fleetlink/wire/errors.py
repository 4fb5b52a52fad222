"""The errors of the wire contract: batches and acks (``WireError``), command messages (``EnvelopeError``)."""

from __future__ import annotations

from fleetlink.common.errors import FleetlinkError


class WireError(FleetlinkError):
    """Bytes that are not a valid batch / ack / record, or a name that cannot be a key segment."""

    def __init__(self, reason: str, *, offset: int | None = None) -> None:
        super().__init__(reason + (f" (at byte {offset})" if offset is not None else ""))
        self.reason = reason
        self.offset = offset


class EnvelopeError(FleetlinkError):
    """Bytes that are not a valid command envelope, reply or status batch.

    ``data`` keeps (a prefix of) the raw bytes for the log or a dead letter.
    """

    def __init__(self, what: str, reason: str, data: bytes = b"") -> None:
        self.what = what
        self.reason = reason
        self.data = data[:256]
        super().__init__(f"malformed {what}: {reason}")


class CommandAuthError(FleetlinkError):
    """A command envelope that is not signed for this site by a trusted key.

    ``kind`` is one of ``unsigned``, ``unknown_key``, ``bad_signature``, ``other_site`` (a
    metric label); the message says what exactly.
    """

    def __init__(self, kind: str, reason: str) -> None:
        self.kind = kind
        self.reason = reason
        super().__init__(f"command refused ({kind}): {reason}")
