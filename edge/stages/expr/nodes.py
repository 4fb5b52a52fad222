"""The syntax tree of a filter expression. Every node keeps its 1-based source column."""

from __future__ import annotations

from dataclasses import dataclass

from fleetlink.edge.stages.paths import Steps


@dataclass(frozen=True, slots=True)
class Const:
    """A literal: bool, number or string."""

    value: bool | int | float | str
    column: int


@dataclass(frozen=True, slots=True)
class Field:
    """A field path into the message (``header.stamp.sec``, ``ranges[0]``)."""

    steps: Steps
    column: int


@dataclass(frozen=True, slots=True)
class Meta:
    """A property of the sample rather than of its message: ``robot``, ``topic`` or ``stamp_ns``."""

    name: str  # robot | topic | stamp_ns
    column: int


@dataclass(frozen=True, slots=True)
class Unary:
    """A unary operator applied to one operand: ``!`` or ``-``."""

    op: str  # ! | -
    operand: Node
    column: int


@dataclass(frozen=True, slots=True)
class Arith:
    """An arithmetic operator: ``+ - * / %``."""

    op: str  # + - * / %
    left: Node
    right: Node
    column: int


@dataclass(frozen=True, slots=True)
class Compare:
    """A comparison: ``== != < <= > >=``."""

    op: str  # == != < <= > >=
    left: Node
    right: Node
    column: int


@dataclass(frozen=True, slots=True)
class Logic:
    """A logical operator: ``&&`` or ``||``."""

    op: str  # && ||
    left: Node
    right: Node
    column: int


@dataclass(frozen=True, slots=True)
class In:
    """A membership test against a list of literals: ``x in [a, b]``."""

    operand: Node
    options: tuple[Const, ...]
    column: int


@dataclass(frozen=True, slots=True)
class Call:
    """A function or method call, such as ``abs(x)``, ``max(a, b)`` or ``ranges.size()``."""

    name: str
    args: tuple[Node, ...]
    column: int


@dataclass(frozen=True, slots=True)
class Quantifier:
    """``any(...)`` or ``all(...)``: a comparison between an array and a scalar, over its elements."""

    name: str  # any | all
    test: Compare
    column: int


Node = Const | Field | Meta | Unary | Arith | Compare | Logic | In | Call | Quantifier
