"""Errors raised by the ``schemas`` package; all carry the ROS type they concern."""

from __future__ import annotations

from fleetlink.common.errors import FleetlinkError


class SchemaError(FleetlinkError):
    """Base class for type-store, schema, conversion and registry errors."""


class UnknownTypeError(SchemaError):
    """A type name is not in the type store (asked for directly or referenced by another type)."""

    def __init__(self, typename: str, referenced_by: str | None = None) -> None:
        self.typename = typename
        self.referenced_by = referenced_by
        where = f" (referenced by {referenced_by})" if referenced_by else ""
        super().__init__(f"unknown ROS type {typename!r}{where}")


class TypeDefinitionError(SchemaError):
    """A message definition cannot be parsed or conflicts with one already loaded."""

    def __init__(self, typename: str, source: str, reason: str) -> None:
        self.typename = typename
        self.source = source
        self.reason = reason
        super().__init__(f"{typename} ({source}): {reason}")


class DecodeError(SchemaError):
    """Bytes that do not form a valid message of ``typename``.

    ``offset`` is the byte offset into the input buffer (CDR: from the first byte of the
    encapsulation header; Avro: from the first byte of the body) where the problem was found.
    ``data`` keeps the raw input so a dead-letter handler has it.
    """

    def __init__(self, typename: str, offset: int, reason: str, data: bytes = b"") -> None:
        self.typename = typename
        self.offset = offset
        self.reason = reason
        self.data = data
        super().__init__(f"cannot decode {typename} at offset {offset}: {reason}")


class ValueRangeError(DecodeError):
    """A value does not fit its target type (e.g. uint64 above 2**63-1 for an Avro long).

    A subclass of :class:`DecodeError`, so one ``except DecodeError`` handles every bad input.
    """

    def __init__(
        self, typename: str, field: str, value: object, reason: str, offset: int, *, data: bytes = b""
    ) -> None:
        self.field = field
        self.value = value
        super().__init__(typename, offset, f"{field} = {value!r} out of range: {reason}", data)


class EncodeError(SchemaError):
    """A datum does not match the Avro schema of ``typename``."""

    def __init__(self, typename: str, reason: str) -> None:
        self.typename = typename
        self.reason = reason
        super().__init__(f"cannot encode {typename}: {reason}")


class RegistryError(SchemaError):
    """The schema registry refused a request or could not be reached."""

    def __init__(self, subject: str, reason: str) -> None:
        self.subject = subject
        self.reason = reason
        super().__init__(f"schema registry, subject {subject!r}: {reason}")


class IncompatibleSchemaError(RegistryError):
    """The registry says a schema is incompatible with the latest registered version."""

    def __init__(self, subject: str, version: int | str, registry_message: str) -> None:
        self.version = version
        self.registry_message = registry_message
        super().__init__(subject, f"schema incompatible with version {version}: {registry_message}")
