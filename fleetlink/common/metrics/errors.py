"""Errors of the metrics and health endpoints."""

from __future__ import annotations

from fleetlink.common.errors import FleetlinkError


class ServeError(FleetlinkError):
    """An HTTP endpoint could not be served (address in use, bad host)."""

    def __init__(self, message: str, *, listen: str) -> None:
        super().__init__(f"{listen}: {message}")
        self.listen = listen
