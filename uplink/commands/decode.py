"""Command record values: Confluent wire format -> writer schema (registry, by id) -> record.

The value must be ``00`` + a 4-byte schema id + an Avro body that the writer schema reads
completely (no trailing bytes). Anything else is undecodable (-> command dead letter); a
registry that cannot be reached is not the record's fault (-> try again later).
"""

from __future__ import annotations

import copy
import io
import json
import threading
from dataclasses import dataclass
from typing import Any, Protocol

import fastavro
from fastavro.read import SchemaResolutionError

from fleetlink.schemas.errors import DecodeError, RegistryError
from fleetlink.schemas.registry import RegistryUnavailableError
from fleetlink.schemas.single_object import confluent_unframe, fingerprint
from fleetlink.uplink.commands.errors import RegistryUnreachableError, UndecodableValueError

_READ_ERRORS = (
    EOFError,
    ValueError,
    TypeError,
    KeyError,
    IndexError,
    UnicodeDecodeError,
    OverflowError,
    SchemaResolutionError,
)


class SchemaSource(Protocol):
    """Where writer schemas are looked up by id (the schema registry)."""

    def schema_by_id(self, schema_id: int) -> dict[str, Any]:
        """The schema registered with ``schema_id``; ``RegistryUnavailableError`` when the registry cannot
        be reached, another ``RegistryError`` when it has no such schema."""


@dataclass(frozen=True, slots=True)
class WriterSchema:
    """The schema a value was written with: its registry id, compact JSON text, Avro fingerprint and parsed
    form."""

    schema_id: int
    text: str
    fingerprint: bytes
    parsed: Any


@dataclass(frozen=True, slots=True)
class DecodedValue:
    """A decoded record value: its writer schema, the Avro body without the Confluent header, and the
    record read from it."""

    writer: WriterSchema
    body: bytes
    record: dict[str, Any]


class CommandDecoder:
    """Decodes record values in the Confluent wire format, fetching each writer schema from the registry
    once."""

    def __init__(self, registry: SchemaSource) -> None:
        self._registry = registry
        self._writers: dict[int, WriterSchema] = {}
        self._lock = threading.Lock()

    def decode(self, value: bytes | None) -> DecodedValue:
        """The writer schema, body and record of ``value``; ``UndecodableValueError`` when it is none (a
        tombstone included), ``RegistryUnreachableError`` when the registry cannot be reached."""
        if value is None:
            raise UndecodableValueError("the record has no value (tombstone): no command", None)
        try:
            schema_id, body = confluent_unframe(value)
        except DecodeError as exc:
            raise UndecodableValueError(f"not the Confluent wire format: {exc}", value) from None
        writer = self.writer(schema_id, value)
        stream = io.BytesIO(body)
        try:
            record = fastavro.schemaless_reader(stream, writer.parsed, None)
        except _READ_ERRORS as exc:
            raise UndecodableValueError(
                f"Avro body does not match schema id {schema_id}: {type(exc).__name__}: {exc}", value
            ) from None
        if stream.tell() != len(body):
            raise UndecodableValueError(
                f"{len(body) - stream.tell()} bytes left over after the Avro record (schema id {schema_id})",
                value,
            )
        if not isinstance(record, dict):
            raise UndecodableValueError(f"schema id {schema_id} is not a record schema", value)
        return DecodedValue(writer, bytes(body), record)

    def writer(self, schema_id: int, raw: bytes | None = None) -> WriterSchema:
        """The writer schema with ``schema_id``, fetched once and cached; ``raw`` is the value quoted when
        the id is unknown or the schema unusable (``UndecodableValueError``)."""
        with self._lock:
            known = self._writers.get(schema_id)
        if known is not None:
            return known
        try:
            schema = self._registry.schema_by_id(schema_id)
        except RegistryUnavailableError as exc:
            raise RegistryUnreachableError(str(exc)) from None
        except RegistryError as exc:
            raise UndecodableValueError(f"unknown schema id {schema_id}: {exc}", raw) from None
        try:
            parsed = fastavro.parse_schema(copy.deepcopy(schema))
        except (ValueError, TypeError, KeyError, fastavro.schema.SchemaParseException) as exc:
            raise UndecodableValueError(f"schema id {schema_id} is not usable Avro: {exc}", raw) from None
        text = json.dumps(schema, separators=(",", ":"))
        writer = WriterSchema(schema_id, text, fingerprint(schema), parsed)
        with self._lock:
            self._writers[schema_id] = writer
        return writer
