"""The schema of a claim-checking mapping's records: the message's, plus ``<field>_ref``.

Every record of the mapping has it, whether its payload went to the object store or not, so a
topic keeps one schema: ``<field>_ref`` is null and ``<field>`` holds the bytes when they were
small; ``<field>`` is empty and ``<field>_ref`` an ``ObjectRef`` when they went to the store.
The record keeps the message's name, so a reader with the plain message schema reads these
records too (Avro schema resolution skips the added field), and the change from the plain
schema to this one is BACKWARD compatible (the new field has a default).
"""

from __future__ import annotations

import copy
from typing import Any

from fleetlink.common.errors import ConfigError
from fleetlink.edge.errors import EdgeError

OBJECT_REF_SCHEMA: dict[str, Any] = {
    "type": "record",
    "name": "ObjectRef",
    "namespace": "fleetlink",
    "doc": "A payload kept in an object store (a claim check): where it is and how to verify it.",
    "fields": [
        {
            "name": "url",
            "type": "string",
            "doc": "where to read it: <endpoint>/<bucket>/<key>, or <public_url>/<key>",
        },
        {"name": "bucket", "type": "string", "doc": "the bucket, for S3 clients"},
        {"name": "key", "type": "string", "doc": "the object key, for S3 clients"},
        {"name": "size", "type": "long", "doc": "bytes"},
        {"name": "sha256", "type": "string", "doc": "SHA-256 of the bytes, lowercase hex"},
        {"name": "content_type", "type": "string", "doc": "MIME type (image/jpeg, image/png, ...)"},
    ],
}


class ClaimCheckError(ConfigError, EdgeError):
    """A claim check does not fit the mapping's message type."""


def ref_field(field: str) -> str:
    """The name of the reference field added beside ``field``: ``<field>_ref``."""
    return f"{field}_ref"


def claim_schema(schema: dict[str, Any], field: str) -> dict[str, Any]:
    """``schema`` (a record) with ``<field>_ref: [null, fleetlink.ObjectRef]`` added; ``field``
    must be one of its top-level fields of type ``bytes``."""
    name = schema.get("name", "?")
    fields = schema.get("fields") if schema.get("type") == "record" else None
    if not isinstance(fields, list):
        raise ClaimCheckError(f"claim_check: {name} is not a record")
    found = next((f for f in fields if f.get("name") == field), None)
    if found is None:
        have = ", ".join(str(f.get("name")) for f in fields)
        raise ClaimCheckError(f"claim_check: {name} has no field {field!r} (it has: {have})")
    if found.get("type") != "bytes":
        raise ClaimCheckError(
            f"claim_check: field {field!r} of {name} is {found.get('ros_type') or found.get('type')}, "
            "not bytes (uint8[])"
        )
    ref = ref_field(field)
    if any(f.get("name") == ref for f in fields):
        raise ClaimCheckError(f"claim_check: {name} already has a field {ref!r}")
    out = copy.deepcopy(schema)
    out["fields"].append(
        {
            "name": ref,
            "type": ["null", copy.deepcopy(OBJECT_REF_SCHEMA)],
            "default": None,
            "doc": f"set when {field} went to the object store ({field} is empty then)",
        }
    )
    return out
