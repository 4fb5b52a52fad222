"""Errors of the edge runtime (start-up problems; per-record problems become dead letters)."""

from __future__ import annotations

from fleetlink.edge.errors import EdgeError


class RuntimeSetupError(EdgeError):
    """The agent cannot start: a directory, the type store or a robot type is unusable."""


class EncodingError(EdgeError):
    """A value does not fit the Avro schema it is written with (``schema`` names it)."""

    def __init__(self, schema: str, reason: str) -> None:
        super().__init__(f"cannot encode a {schema} record: {reason}")
        self.schema = schema
        self.reason = reason
