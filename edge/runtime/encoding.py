"""Avro writers keyed by fingerprint: one per ROS type (generated converters) or derived schema.

``AvroWriter`` holds a schema's JSON text and its 8-byte CRC-64-AVRO fingerprint (the one the
single-object header carries, and the uplink registers under ``<topic>-value``) and writes
datums with fastavro. A ROS type's own schema needs no writer: its codec's generated
``cdr_to_avro`` makes the body straight from the CDR bytes.
"""

from __future__ import annotations

import copy
import io
import json
from dataclasses import dataclass
from typing import Any

import fastavro

from fleetlink.edge.runtime.errors import EncodingError
from fleetlink.schemas.single_object import fingerprint


def schema_json(schema: dict[str, Any]) -> str:
    """The schema text shipped to the uplink (compact, key order kept)."""
    return json.dumps(schema, separators=(",", ":"), ensure_ascii=False)


@dataclass(frozen=True, slots=True)
class SchemaIdentity:
    """A schema's 8-byte CRC-64-AVRO fingerprint and its JSON text."""

    fingerprint: bytes
    json: str


def identity_of(schema: dict[str, Any]) -> SchemaIdentity:
    """The fingerprint and JSON text of ``schema``."""
    return SchemaIdentity(fingerprint(schema), schema_json(schema))


class AvroWriter:
    """Writes datums of one (derived) schema as Avro binary bodies."""

    def __init__(self, schema: dict[str, Any]) -> None:
        self.schema = schema
        self.name = str(schema.get("name", "record"))
        self.identity = identity_of(schema)
        self._parsed = fastavro.parse_schema(copy.deepcopy(schema))

    @property
    def fingerprint(self) -> bytes:
        """The schema's 8-byte CRC-64-AVRO fingerprint."""
        return self.identity.fingerprint

    def body(self, datum: Any) -> bytes:
        """``datum`` as an Avro binary body; raises ``EncodingError`` when it does not fit the schema."""
        out = io.BytesIO()
        try:
            fastavro.schemaless_writer(out, self._parsed, datum)
        except (ValueError, TypeError, KeyError, AttributeError, OverflowError) as exc:
            raise EncodingError(self.name, f"{type(exc).__name__}: {exc}") from exc
        return out.getvalue()
