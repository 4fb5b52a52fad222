"""pydantic validation errors -> ``FieldProblem`` lists with config-file style paths.

Paths are written like ``fleetlink validate`` writes them (``fleetlink.common.configfile.format_path``:
``mappings[0].stages[1].hz``); the tag pydantic adds for a discriminated union (the stage
``type``) is left out, so the path names keys of the document only.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from pydantic import ValidationError

from fleetlink.common.configfile import PathPart, format_path
from fleetlink.edge.admin.errors import FieldProblem

_PREFIXES = ("Value error, ", "Assertion failed, ")


def document_path(loc: Sequence[Any], data: Any) -> tuple[PathPart, ...]:
    """``loc`` with the parts that are not keys of ``data`` (union tags) removed."""
    out: list[PathPart] = []
    node = data
    for part in loc:
        if not isinstance(part, str | int):
            continue
        if isinstance(node, dict) and isinstance(part, str) and part not in node and node.get("type") == part:
            continue  # a discriminated union's tag
        out.append(part)
        if isinstance(node, dict):
            node = node.get(part)
        elif isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node):
            node = node[part]
        else:
            node = None
    return tuple(out)


def message_of(error: Any) -> str:
    """A pydantic error's message as reported: an unknown key explained, pydantic's ``Value error, ``
    and ``Assertion failed, `` prefixes removed."""
    if error["type"] == "extra_forbidden":
        return "unknown key (not allowed here; check the spelling)"
    text = str(error["msg"])
    for prefix in _PREFIXES:
        text = text.removeprefix(prefix)
    return text


def problems_from(
    exc: ValidationError, data: Any, *, body_prefix: tuple[PathPart, ...] | None = None
) -> tuple[FieldProblem, ...]:
    """One ``FieldProblem`` per error of validating ``data``. Errors under ``body_prefix`` (where
    the request's body sits in ``data``) get a body-relative ``path``; others keep the full path."""
    out = []
    for error in exc.errors(include_url=False):
        full = document_path(error["loc"], data)
        inside = body_prefix is not None and full[: len(body_prefix)] == body_prefix
        rel = full[len(body_prefix) :] if inside and body_prefix is not None else full
        out.append(
            FieldProblem(path=format_path(rel), message=message_of(error), config_path=format_path(full))
        )
    return tuple(out)
