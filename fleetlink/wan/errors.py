"""The one error of the wire contract."""

from __future__ import annotations

from fleetlink.errors import FleetlinkError


class WireError(FleetlinkError):
    """Bytes that are not a valid batch / ack / record, or a name that cannot be a key segment."""

    def __init__(self, reason: str, *, offset: int | None = None) -> None:
        super().__init__(reason + (f" (at byte {offset})" if offset is not None else ""))
        self.reason = reason
        self.offset = offset

