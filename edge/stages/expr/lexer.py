"""Tokens of the filter expression language, each with its 1-based column."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

from fleetlink.edge.stages.errors import ExpressionError

TokenKind = Literal["num", "str", "ident", "meta", "op", "end"]

KEYWORDS = frozenset({"true", "false", "in"})
OPERATORS = (
    "==",
    "!=",
    "<=",
    ">=",
    "&&",
    "||",
    "<",
    ">",
    "!",
    "+",
    "-",
    "*",
    "/",
    "%",
    "(",
    ")",
    "[",
    "]",
    ",",
    ".",
)

_NUMBER = re.compile(r"(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_SPACE = re.compile(r"\s+")
_ESCAPES = {"n": "\n", "t": "\t", "r": "\r", "\\": "\\", '"': '"', "'": "'", "0": "\0"}


@dataclass(frozen=True, slots=True)
class Token:
    """One token: its kind, its source text, its 1-based column and, for literals, its value."""

    kind: TokenKind
    text: str
    column: int
    value: int | float | str | None = None


def _string(source: str, start: int) -> tuple[Token, int]:
    quote = source[start]
    out: list[str] = []
    pos = start + 1
    while pos < len(source):
        char = source[pos]
        if char == quote:
            return Token("str", source[start : pos + 1], start + 1, "".join(out)), pos + 1
        if char == "\\":
            if pos + 1 >= len(source):
                break
            escaped = _ESCAPES.get(source[pos + 1])
            if escaped is None:
                raise ExpressionError(
                    f"unknown escape \\{source[pos + 1]} in string", expression=source, column=pos + 1
                )
            out.append(escaped)
            pos += 2
            continue
        out.append(char)
        pos += 1
    raise ExpressionError("string is not closed", expression=source, column=start + 1)


def tokenize(source: str) -> list[Token]:
    """Split ``source`` into tokens; the last one is ``end``. Raises ``ExpressionError``."""
    tokens: list[Token] = []
    pos = 0
    while True:
        space = _SPACE.match(source, pos)
        if space:
            pos = space.end()
        if pos >= len(source):
            tokens.append(Token("end", "", len(source) + 1))
            return tokens
        char = source[pos]
        if char.isdigit() or (char == "." and source[pos + 1 : pos + 2].isdigit()):
            match = _NUMBER.match(source, pos)
            if match is None:  # pragma: no cover - the first character is a digit or .digit
                raise ExpressionError("invalid number", expression=source, column=pos + 1)
            text = match.group()
            value: int | float = float(text) if any(c in text for c in ".eE") else int(text)
            end = match.end()
            if end < len(source) and (source[end].isalnum() or source[end] == "_"):
                raise ExpressionError(
                    f"invalid number {source[pos : end + 1]!r}", expression=source, column=pos + 1
                )
            tokens.append(Token("num", text, pos + 1, value))
            pos = end
        elif char in "\"'":
            token, pos = _string(source, pos)
            tokens.append(token)
        elif char == "@":
            match = _IDENT.match(source, pos + 1)
            if match is None:
                raise ExpressionError(
                    "expected a name after '@' (@robot, @topic, @stamp_ns)", expression=source, column=pos + 1
                )
            tokens.append(Token("meta", match.group(), pos + 1))
            pos = match.end()
        elif (ident := _IDENT.match(source, pos)) is not None:
            kind: TokenKind = "op" if ident.group() in KEYWORDS else "ident"
            tokens.append(Token(kind, ident.group(), pos + 1))
            pos = ident.end()
        else:
            op = next((o for o in OPERATORS if source.startswith(o, pos)), None)
            if op is None:
                hint = " (use && or ||)" if char in "&|" else " (use == to compare)" if char == "=" else ""
                raise ExpressionError(
                    f"unexpected character {char!r}{hint}", expression=source, column=pos + 1
                )
            tokens.append(Token("op", op, pos + 1))
            pos += len(op)
