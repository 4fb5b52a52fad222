"""Kafka record values in the Confluent wire format ↔ Avro datums, schemas found by id.

``decode`` reads ``00`` + 4-byte schema id + Avro body with the writer schema the lookup gives
for that id (the registry, in practice); ``encode`` writes a datum the other way. Parsed schemas
are cached per id. No network of its own: the lookup is passed in.
"""

from __future__ import annotations

import copy
import io
import threading
from collections.abc import Callable
from typing import Any

import fastavro

from fleetlink.schemas.errors import DecodeError, EncodeError
from fleetlink.schemas.single_object import confluent_frame, confluent_unframe

__all__ = ["ConfluentValues"]

_READ_ERRORS = (EOFError, ValueError, TypeError, KeyError, IndexError, UnicodeDecodeError, OverflowError)


class ConfluentValues:
    """Decodes and encodes Confluent-framed Avro values, with parsed schemas cached per id; thread-safe."""

    def __init__(self, schema_by_id: Callable[[int], dict[str, Any]]) -> None:
        self._schema_by_id = schema_by_id
        self._parsed: dict[int, Any] = {}
        self._lock = threading.Lock()

    def parsed(self, schema_id: int, schema: dict[str, Any] | None = None) -> Any:
        """The parsed schema of ``schema_id`` (looked up unless given)."""
        with self._lock:
            cached = self._parsed.get(schema_id)
        if cached is not None:
            return cached
        raw = schema if schema is not None else self._schema_by_id(schema_id)
        parsed = fastavro.parse_schema(copy.deepcopy(raw))
        with self._lock:
            self._parsed[schema_id] = parsed
        return parsed

    def decode(self, data: bytes) -> tuple[int, Any]:
        """(schema id, datum) of a value; FramingError (a DecodeError) when it is not Confluent-framed."""
        schema_id, body = confluent_unframe(data)
        parsed = self.parsed(schema_id)
        reader = io.BytesIO(body)
        try:
            datum = fastavro.schemaless_reader(reader, parsed, None)
        except _READ_ERRORS as exc:
            raise DecodeError(f"schema id {schema_id}", reader.tell(), str(exc), data) from None
        if reader.tell() != len(body):
            raise DecodeError(
                f"schema id {schema_id}", reader.tell(), f"{len(body) - reader.tell()} bytes left over", data
            )
        return schema_id, datum

    def encode(self, schema_id: int, schema: dict[str, Any], datum: Any) -> bytes:
        """A datum (already checked against ``schema``) as a Confluent-framed value."""
        out = io.BytesIO()
        try:
            fastavro.schemaless_writer(out, self.parsed(schema_id, schema), datum)
        except (ValueError, TypeError, KeyError, AttributeError, OverflowError) as exc:
            raise EncodeError(str(schema.get("name", "?")), str(exc)) from None
        return confluent_frame(schema_id, out.getvalue())
