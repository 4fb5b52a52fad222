"""What can go wrong with the object store."""

from __future__ import annotations

from fleetlink.common.errors import FleetlinkError


class ObjectStoreError(FleetlinkError):
    """A request to the object store failed. ``retriable``: the store may take it later (it is
    down, slow or overloaded: no answer, 5xx, 429, a timeout); otherwise it refused the request
    (wrong credentials, no such bucket, a key or body it does not take) and will again."""

    def __init__(self, message: str, *, retriable: bool, status: int | None = None) -> None:
        super().__init__(message)
        self.retriable = retriable
        self.status = status
