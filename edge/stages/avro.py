"""Just enough Avro schema handling for the stages: named types, field-path resolution,
self-contained copies of sub-schemas, and deterministic names for derived records.

Schemas are the parsed-JSON form (dicts, lists, strings). Nested named types may be defined
once and referenced by name later, with Avro's namespace rules.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from fleetlink.edge.stages.errors import FieldPathError, StageConfigError
from fleetlink.edge.stages.paths import Step, path_text

PRIMITIVES = frozenset({"null", "boolean", "int", "long", "float", "double", "bytes", "string"})
NUMERIC = frozenset({"int", "long", "float", "double"})
NAMED = frozenset({"record", "enum", "fixed", "error"})
_PRIMITIVE_KINDS = {"boolean": "bool", "string": "string", "bytes": "bytes", "null": "null"}


@dataclass(frozen=True, slots=True)
class Node:
    """A schema position, resolved: ``schema`` is a primitive name, a dict or a union list (never a
    reference), ``namespace`` the enclosing namespace for names written inside it."""

    schema: Any
    namespace: str | None


def _fullname(name: str, namespace: str | None) -> str:
    if "." in name or not namespace:
        return name
    return f"{namespace}.{name}"


def _namespace_of(fullname: str) -> str | None:
    return fullname.rpartition(".")[0] or None


class SchemaIndex:
    """All named types defined anywhere in one schema, by full name."""

    def __init__(self, root: Any) -> None:
        self.root = root
        self.named: dict[str, dict[str, Any]] = {}
        self._collect(root, None)

    def _collect(self, schema: Any, namespace: str | None) -> None:
        if isinstance(schema, list):
            for branch in schema:
                self._collect(branch, namespace)
            return
        if not isinstance(schema, dict):
            return
        kind = schema.get("type")
        if kind in NAMED:
            full = _fullname(str(schema["name"]), schema.get("namespace") or namespace)
            self.named[full] = schema
            namespace = _namespace_of(full)
            for field in schema.get("fields", ()) if kind in ("record", "error") else ():
                self._collect(field["type"], namespace)
        elif kind == "array":
            self._collect(schema["items"], namespace)
        elif kind == "map":
            self._collect(schema["values"], namespace)
        elif isinstance(kind, dict | list):
            self._collect(kind, namespace)

    def resolve(self, schema: Any, namespace: str | None) -> Node:
        """Follow references (``"pkg.msg.Header"``) and ``{"type": {...}}`` wrappers."""
        while True:
            if isinstance(schema, str):
                if schema in PRIMITIVES:
                    return Node(schema, namespace)
                full = _fullname(schema, namespace)
                if full not in self.named:
                    full = schema
                if full not in self.named:
                    raise StageConfigError(f"schema refers to unknown type {schema!r}")
                return Node(self.named[full], _namespace_of(full))
            if isinstance(schema, dict):
                kind = schema.get("type")
                if isinstance(kind, dict | list) or (
                    isinstance(kind, str)
                    and kind not in PRIMITIVES
                    and kind not in NAMED
                    and kind not in ("array", "map")
                ):
                    schema = kind
                    continue
                if kind in NAMED:
                    full = schema_fullname(schema, namespace)
                    return Node(schema, _namespace_of(full))
                if kind in PRIMITIVES:
                    return Node(kind, namespace)
            return Node(schema, namespace)

    def fullname_of(self, node: Node) -> str | None:
        """The full name of the named type at ``node``; ``None`` when it is not a named type."""
        if isinstance(node.schema, dict) and node.schema.get("type") in NAMED:
            return _fullname(str(node.schema["name"]), node.namespace)
        return None


def schema_fullname(schema: dict[str, Any], namespace: str | None) -> str:
    """The full name of the named ``schema``, in ``namespace`` unless it names its own."""
    return _fullname(str(schema["name"]), schema.get("namespace") or namespace)


def _nullable_inner(node: Node, index: SchemaIndex) -> Node:
    if isinstance(node.schema, list):
        branches = [b for b in node.schema if b != "null"]
        if len(branches) == 1:
            return index.resolve(branches[0], node.namespace)
    return node


def kind_of(node: Node) -> str:
    """number, bool, string, bytes, array, map, record, null or unknown."""
    schema = node.schema
    if isinstance(schema, str):
        if schema in NUMERIC:
            return "number"
        return _PRIMITIVE_KINDS.get(schema, "unknown")
    if isinstance(schema, dict):
        kind = schema.get("type")
        return {
            "record": "record",
            "error": "record",
            "enum": "string",
            "fixed": "bytes",
            "array": "array",
            "map": "map",
        }.get(str(kind), "unknown")
    return "unknown"


def describe(node: Node, index: SchemaIndex) -> str:
    """A short human name for a schema position, for error messages."""
    full = index.fullname_of(node)
    if full is not None:
        return f"record {full!r}" if kind_of(node) == "record" else full
    if isinstance(node.schema, dict):
        return str(node.schema.get("type"))
    return json.dumps(node.schema)


def root_node(schema: Any) -> tuple[SchemaIndex, Node]:
    """Index ``schema`` and resolve its top; refuses anything but a well-formed record schema."""
    try:
        index = SchemaIndex(schema)
        node = index.resolve(schema, None)
        fields = node.schema.get("fields") if isinstance(node.schema, dict) else None
        malformed = not isinstance(fields, list) or any(
            not isinstance(f, dict) or "name" not in f or "type" not in f for f in fields
        )
    except (KeyError, TypeError, AttributeError) as exc:
        raise StageConfigError(f"input is not a valid Avro schema ({type(exc).__name__}: {exc})") from None
    if kind_of(node) != "record":
        raise StageConfigError("stages need a record schema as input")
    if malformed:
        raise StageConfigError("input is not a valid Avro schema: a record field lacks 'name' or 'type'")
    return index, node


def resolve_path(index: SchemaIndex, root: Node, steps: Sequence[Step]) -> Node:
    """The schema position at ``steps``; raises ``FieldPathError`` naming the path and the type."""
    text = path_text(steps)
    node = root
    root_name = index.fullname_of(root)
    for depth, step in enumerate(steps):
        node = _nullable_inner(node, index)
        kind = kind_of(node)
        where = path_text(steps[:depth]) or "the message"
        if isinstance(step, str):
            if kind != "record":
                raise FieldPathError(
                    f"field path {text!r}: {where} is {describe(node, index)}, which has no field {step!r}",
                    path=text,
                    type_name=root_name,
                )
            fields = node.schema.get("fields", [])
            match = next((f for f in fields if f["name"] == step), None)
            if match is None:
                names = ", ".join(f["name"] for f in fields)
                raise FieldPathError(
                    f"field path {text!r}: {describe(node, index)} has no field {step!r} (it has: {names})",
                    path=text,
                    type_name=root_name,
                )
            node = index.resolve(match["type"], node.namespace)
        elif kind == "array":
            node = index.resolve(node.schema["items"], node.namespace)
        elif kind == "bytes":
            node = Node("int", node.namespace)
        else:
            raise FieldPathError(
                f"field path {text!r}: {where} is {describe(node, index)}, not an array, so [{step}] "
                "cannot index it",
                path=text,
                type_name=root_name,
            )
    return _nullable_inner(node, index)


def copy_self_contained(node: Node, index: SchemaIndex, defined: set[str]) -> Any:  # noqa: PLR0911
    """A copy of the schema at ``node`` usable on its own: every named type it uses is defined on
    first use (with its full name) and referenced by full name after; ``defined`` is shared by
    all copies that go into one output schema."""
    schema = node.schema
    if isinstance(schema, str):
        return schema
    if isinstance(schema, list):
        return [copy_self_contained(index.resolve(b, node.namespace), index, defined) for b in schema]
    kind = schema.get("type")
    if kind in NAMED:
        full = _fullname(str(schema["name"]), node.namespace)
        if full in defined:
            return full
        defined.add(full)
        out = {k: v for k, v in schema.items() if k not in ("name", "namespace", "fields")}
        out["name"] = full
        if kind in ("record", "error"):
            out["fields"] = [
                {
                    **{k: v for k, v in f.items() if k != "type"},
                    "type": copy_self_contained(index.resolve(f["type"], node.namespace), index, defined),
                }
                for f in schema.get("fields", [])
            ]
        return out
    if kind == "array":
        return {
            **schema,
            "items": copy_self_contained(index.resolve(schema["items"], node.namespace), index, defined),
        }
    if kind == "map":
        return {
            **schema,
            "values": copy_self_contained(index.resolve(schema["values"], node.namespace), index, defined),
        }
    return dict(schema)


def short_hash(parts: Iterable[object], length: int = 8) -> str:
    """A stable hex digest of ``parts`` (JSON, sorted keys) for naming derived records."""
    text = json.dumps(list(parts), sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:length]
