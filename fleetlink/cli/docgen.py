"""The configuration reference, generated from the config models (``docs/reference/config.md``).

    python -m fleetlink.cli.docgen > docs/reference/config.md

A unit test regenerates it and compares, so the reference never drifts from the code. Each
field's text is its ``Field(description=...)`` or the docstring written under it.
"""

from __future__ import annotations

import ast
import inspect
import textwrap
import types
import typing
from collections.abc import Iterator
from functools import cache
from typing import Any

from pydantic import BaseModel, ByteSize, PlainSerializer
from pydantic_core import PydanticUndefined

from fleetlink.cli.configs import KINDS, model_for


@cache
def attribute_docs(cls: type) -> dict[str, str]:
    """Docstrings written under class attributes (``x: int = 1`` then ``\"\"\"text\"\"\"``)."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if klass in (object, BaseModel) or not issubclass(klass, BaseModel):
            continue
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError, SyntaxError):
            continue
        body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
        for node, following in zip(body, [*body[1:], None], strict=True):
            if (
                isinstance(node, ast.AnnAssign)
                and isinstance(node.target, ast.Name)
                and isinstance(following, ast.Expr)
                and isinstance(following.value, ast.Constant)
                and isinstance(following.value.value, str)
            ):
                docs[node.target.id] = " ".join(following.value.value.split())
    return docs


def type_text(annotation: Any) -> str:  # noqa: PLR0911 - one return per kind of annotation
    """A field's type as the reference table shows it (``list of str``, ``map of str → section`` ...)."""
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if origin is typing.Annotated:
        return type_text(args[0])
    if origin is typing.Literal:
        return " \\| ".join(f"`{a}`" for a in args)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(type_text(a) for a in args if a is not type(None)) + (
            " (optional)" if type(None) in args else ""
        )
    if origin in (list, tuple, set, frozenset):
        return f"list of {type_text(args[0])}" if args else "list"
    if origin is dict:
        return f"map of {type_text(args[0])} → {type_text(args[1])}" if args else "map"
    if isinstance(annotation, type):
        if issubclass(annotation, BaseModel):
            return "section"
        return annotation.__name__
    return str(annotation).replace("typing.", "")


def _models_in(annotation: Any) -> list[type[BaseModel]]:
    found: list[type[BaseModel]] = []
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        found.append(annotation)
    for arg in typing.get_args(annotation):
        found.extend(_models_in(arg))
    return found


def _serializer(field: Any) -> Any:
    return next((m.func for m in field.metadata if isinstance(m, PlainSerializer)), None)


def _is_duration(meta: Any) -> bool:
    schema = getattr(meta, "json_schema", None) or {}
    return str(schema.get("description", "")).startswith("a duration")


def _duration_in(annotation: Any) -> bool:
    """Whether a duration type is inside ``annotation`` (``DurationNs | None``)."""
    args = typing.get_args(annotation)
    if typing.get_origin(annotation) is typing.Annotated and any(_is_duration(m) for m in args[1:]):
        return True
    return any(_duration_in(a) for a in args)


def _field_type(field: Any) -> str:
    if any(_is_duration(meta) for meta in field.metadata):
        return "duration"
    if _duration_in(field.annotation):
        return "duration (optional)" if type(None) in typing.get_args(field.annotation) else "duration"
    if isinstance(field.annotation, type) and issubclass(field.annotation, ByteSize):
        return "size"
    models = _models_in(field.annotation)
    if len(models) > 1:
        kinds = [
            str(typing.get_args(m.model_fields["type"].annotation)[0])
            for m in models
            if "type" in m.model_fields
        ]
        what = "stage" if kinds else "section"
        listed = f" ({', '.join(kinds)}: see docs/stages.md)" if kinds else ""
        return f"list of {what}{listed}" if typing.get_origin(field.annotation) is list else what
    return type_text(field.annotation)


def _default(field: Any) -> str:
    if field.default is PydanticUndefined:
        return "required" if field.default_factory is None else "(computed)"
    value = field.default
    if isinstance(value, BaseModel):
        return "(section defaults)"
    serialize = _serializer(field)
    if serialize is not None and value is not None:
        value = serialize(value)
    elif isinstance(value, ByteSize):
        value = value.human_readable(separator="")
    return f"`{value!r}`" if value not in ([], {}, None) else f"`{value}`"


def rows(model: type[BaseModel], prefix: str = "") -> Iterator[tuple[str, str, str, str]]:
    """The reference rows (key, type, default, meaning) of ``model``'s fields, nested sections included."""
    docs = attribute_docs(model)
    for name, field in model.model_fields.items():
        key = field.alias or name
        path = f"{prefix}{key}"
        text = field.description or docs.get(name, "")
        yield path, _field_type(field), _default(field), text
        nested = _models_in(field.annotation)
        if len(nested) != 1:
            continue  # unions of models (stages) are documented on their own
        origin = typing.get_origin(field.annotation)
        marker = "[]." if origin is list else ".<name>." if origin is dict else "."
        yield from rows(nested[0], f"{path}{marker}")


def render() -> str:
    """The whole configuration reference, as Markdown, for every kind of config."""
    out = [
        "# Configuration reference",
        "",
        "Generated from the config models by `python -m fleetlink.cli.docgen`; do not edit by hand.",
        "Every file is checked with `fleetlink validate FILE` as start-up would (errors name the YAML",
        "path): keys and values, then this machine's folders, message packages, mapping types and Zenoh",
        "config files (`--no-host-checks` skips those). Durations are text with a unit (`250ms`, `5s`,",
        "`2m`) or seconds; sizes take `KiB`, `MiB`, `GiB`. Relative paths are taken from the working",
        "folder.",
        "",
        "Any value can be changed at start without editing the file: `--set KEY=VALUE` on `validate`",
        "and `edge|uplink|repeater run`, and one `KEY=VALUE` per line in `$FLEETLINK_SET` (for units",
        "and containers). KEY is the YAML path as below (`mappings[0].to`; a key holding a dot in",
        'quotes: `kafka.producer_overrides."batch.size"`), VALUE is YAML:',
        "`--set zenoh.connect=[tcp/10.0.0.5:7447]`. The file comes first, then `$FLEETLINK_SET`, then",
        "`--set` in order.",
        "",
    ]
    for kind in KINDS:
        model = model_for(kind)
        out += [f"## {kind} (`{model.__module__}.{model.__name__}`)", ""]
        if model.__doc__:
            out += [" ".join(model.__doc__.split()), ""]
        out += ["| key | type | default | meaning |", "|---|---|---|---|"]
        out += [f"| `{p}` | {t} | {d} | {m} |" for p, t, d, m in rows(model)]
        out.append("")
    return "\n".join(out)


if __name__ == "__main__":
    print(render(), end="")
