"""Kafka topic and key templates: ``fleet.{sensor}``, ``fleet.tasks.{msg.zone}``, ``{robot}``.

A template is literal text with placeholders: ``{capture}`` (a capture of the mapping's topic
pattern) or ``{msg.path.to.field}`` (a field of the decoded message). ``{{`` and ``}}`` are
literal braces. Captures are filled in when a topic matches (``bind``); message fields are
filled in per record (``render``). A multi-segment capture (``{rest*}`` matching ``a/b``)
renders as ``a.b`` in a Kafka topic, since Kafka topic names have no '/'.

Kafka topic names: 1 to 249 characters from ``[a-zA-Z0-9._-]``, and not ``.`` or ``..``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from fleetlink.edge.errors import MappingError, RenderError

_PLACEHOLDER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)*")


@dataclass(frozen=True, slots=True)
class Placeholder:
    """``{name}``: a capture, or ``{msg.a.b}``: the message field at path ``("a", "b")``."""

    name: str

    @property
    def field_path(self) -> tuple[str, ...] | None:
        """The message field path of a ``{msg...}`` placeholder; ``None`` for a capture."""
        if self.name.startswith("msg."):
            return tuple(self.name.split(".")[1:])
        return None


Part = str | Placeholder


def format_field(value: Any) -> str:
    """Text of a message field in a topic or key; raises ``ValueError`` for unusable values."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return value
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"{value!r} cannot name a topic or key")
        return str(int(value)) if value.is_integer() else repr(value)
    kind = type(value).__name__
    raise ValueError(f"a {kind} value cannot be used in a template (use a text or number field)")


def lookup_field(fields: Mapping[str, Any], path: tuple[str, ...]) -> Any:
    """The value at ``path`` in a nested mapping; raises ``KeyError`` naming the missing step."""
    node: Any = fields
    for depth, step in enumerate(path):
        if not isinstance(node, Mapping) or step not in node:
            raise KeyError("msg." + ".".join(path[: depth + 1]))
        node = node[step]
    return node


@dataclass(frozen=True, slots=True)
class Template:
    """A parsed template. Build with ``Template.parse``."""

    text: str
    parts: tuple[Part, ...]

    @classmethod
    def parse(cls, text: str, *, mapping: str | None = None, what: str = "template") -> Template:
        """Parse ``text``; raises ``MappingError`` naming the mapping and the template."""

        def fail(reason: str) -> MappingError:
            return MappingError(f"{what} {text!r}: {reason}", mapping=mapping, template=text)

        parts: list[Part] = []
        literal: list[str] = []
        i = 0
        while i < len(text):
            char = text[i]
            if text.startswith("{{", i) or text.startswith("}}", i):
                literal.append(char)
                i += 2
            elif char == "{":
                end = text.find("}", i)
                if end < 0:
                    raise fail(f"unclosed '{{' at column {i + 1}")
                name = text[i + 1 : end].strip()
                if _PLACEHOLDER.fullmatch(name) is None:
                    raise fail(f"{{{name}}} is not a capture name or a msg.field path")
                if "." in name and not name.startswith("msg."):
                    raise fail(f"{{{name}}}: dotted paths read message fields and start with 'msg.'")
                if name == "msg":
                    raise fail("{msg} needs a field path, such as {msg.zone}")
                if literal:
                    parts.append("".join(literal))
                    literal = []
                parts.append(Placeholder(name))
                i = end + 1
            elif char == "}":
                raise fail(f"unmatched '}}' at column {i + 1} (write '}}}}' for a literal brace)")
            else:
                literal.append(char)
                i += 1
        if literal:
            parts.append("".join(literal))
        return cls(text=text, parts=tuple(parts))

    @property
    def captures(self) -> frozenset[str]:
        """Capture names this template uses."""
        return frozenset(p.name for p in self.parts if isinstance(p, Placeholder) and p.field_path is None)

    @property
    def field_paths(self) -> tuple[tuple[str, ...], ...]:
        """Message-field paths this template reads, in order, without repeats."""
        out: list[tuple[str, ...]] = []
        for part in self.parts:
            path = part.field_path if isinstance(part, Placeholder) else None
            if path is not None and path not in out:
                out.append(path)
        return tuple(out)

    @property
    def literal_text(self) -> str:
        """The template's literal parts, concatenated (for static checks)."""
        return "".join(p for p in self.parts if isinstance(p, str))

    @property
    def is_literal(self) -> bool:
        """Whether the template has no placeholders."""
        return all(isinstance(p, str) for p in self.parts)

    def bind(self, values: Mapping[str, str], *, for_topic: bool = False) -> Template:
        """Fill in the captures present in ``values``; ``for_topic`` turns '/' into '.'."""
        parts: list[Part] = []
        for part in self.parts:
            piece: Part = part
            if isinstance(part, Placeholder) and part.field_path is None and part.name in values:
                value = values[part.name]
                piece = value.strip("/").replace("/", ".") if for_topic else value
            if isinstance(piece, str) and parts and isinstance(parts[-1], str):
                parts[-1] = parts[-1] + piece
            elif piece != "":
                parts.append(piece)
        return Template(text=self.text, parts=tuple(parts))

    def render(self, fields: Mapping[str, Any] | None, *, mapping: str) -> str:
        """The text with message fields filled in. Captures must already be bound.

        Raises ``RenderError`` (a per-record problem) when a field is missing or unusable.
        """
        out: list[str] = []
        for part in self.parts:
            if isinstance(part, str):
                out.append(part)
                continue
            path = part.field_path
            if path is None:
                raise RenderError(
                    f"capture {{{part.name}}} was never bound", mapping=mapping, template=self.text
                )
            if fields is None:
                raise RenderError(
                    f"needs message field {part.name} but no message was given",
                    mapping=mapping,
                    template=self.text,
                )
            try:
                out.append(format_field(lookup_field(fields, path)))
            except KeyError as exc:
                raise RenderError(
                    f"the message has no field {exc.args[0]}", mapping=mapping, template=self.text
                ) from None
            except ValueError as exc:
                raise RenderError(f"field {part.name}: {exc}", mapping=mapping, template=self.text) from None
        return "".join(out)
