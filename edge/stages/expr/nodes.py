"""The syntax tree of a filter expression. Every node keeps its 1-based source column."""

from __future__ import annotations

from dataclasses import dataclass

from fleetlink.edge.stages.paths import Steps


@dataclass(frozen=True, slots=True)
class Const:
    value: bool | int | float | str
    column: int


@dataclass(frozen=True, slots=True)
class Field:
    steps: Steps
    column: int


@dataclass(frozen=True, slots=True)
class Meta:
    name: str  # robot | topic | stamp_ns
    column: int


@dataclass(frozen=True, slots=True)
class Unary:
    op: str  # ! | -
    operand: Node
    column: int


@dataclass(frozen=True, slots=True)
class Arith:
    op: str  # + - * / %
    left: Node
    right: Node
    column: int


@dataclass(frozen=True, slots=True)
class Compare:
    op: str  # == != < <= > >=
    left: Node
    right: Node
    column: int


@dataclass(frozen=True, slots=True)
class Logic:
    op: str  # && ||
    left: Node
    right: Node
    column: int


@dataclass(frozen=True, slots=True)
class In:
    operand: Node
    options: tuple[Const, ...]
    column: int


@dataclass(frozen=True, slots=True)
class Call:
    name: str
    args: tuple[Node, ...]
    column: int


@dataclass(frozen=True, slots=True)
class Quantifier:
    name: str  # any | all
    test: Compare
    column: int


Node = Const | Field | Meta | Unary | Arith | Compare | Logic | In | Call | Quantifier
