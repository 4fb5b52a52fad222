"""Static checks of a parsed expression: operand kinds and, given the message's Avro schema,
field paths. Kinds: number, string, bool, bytes, array, record, map, null, unknown.

Without a schema every field is ``unknown`` and only literal misuse is caught (``1 && true``);
with one, a path the type does not have, or a kind mismatch (``header.frame_id > 3``), is a
config error naming the column.
"""

from __future__ import annotations

from collections.abc import Callable

from fleetlink.edge.stages.errors import ExpressionError, FieldPathError
from fleetlink.edge.stages.expr.nodes import (
    Arith,
    Call,
    Compare,
    Const,
    Field,
    In,
    Logic,
    Meta,
    Node,
    Quantifier,
    Unary,
)
from fleetlink.edge.stages.paths import Steps

FieldKind = Callable[[Steps], str]
"""Field path -> kind; raises ``FieldPathError`` for a path the message type does not have."""

SCALARS = frozenset({"number", "string", "bool", "bytes"})
SEQUENCES = frozenset({"array", "bytes"})


def const_kind(value: object) -> str:
    """The kind of a literal: ``bool``, ``number`` or ``string``."""
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int | float):
        return "number"
    return "string"


class _Checker:
    def __init__(self, source: str, field_kind: FieldKind | None) -> None:
        self.source = source
        self.field_kind = field_kind

    def fail(self, reason: str, column: int) -> ExpressionError:
        return ExpressionError(reason, expression=self.source, column=column)

    def need(self, kind: str, allowed: frozenset[str], what: str, column: int) -> None:
        if kind != "unknown" and kind not in allowed:
            raise self.fail(f"{what} needs {' or '.join(sorted(allowed))}, got {kind}", column)

    def kind(self, node: Node) -> str:  # noqa: PLR0911, PLR0912 - one branch per node type
        if isinstance(node, Const):
            return const_kind(node.value)
        if isinstance(node, Meta):
            return "number" if node.name == "stamp_ns" else "string"
        if isinstance(node, Field):
            if self.field_kind is None:
                return "unknown"
            try:
                return self.field_kind(node.steps)
            except FieldPathError as exc:
                raise self.fail(str(exc), node.column) from None
        if isinstance(node, Unary):
            operand = self.kind(node.operand)
            where = start_column(node.operand)
            if node.op == "!":
                self.need(operand, frozenset({"bool"}), "'!'", where)
                return "bool"
            self.need(operand, frozenset({"number"}), "unary '-'", where)
            return "number"
        if isinstance(node, Arith):
            left, right = self.kind(node.left), self.kind(node.right)
            if node.op == "+" and "string" in (left, right):
                self.need(left, frozenset({"string"}), "'+' on text", start_column(node.left))
                self.need(right, frozenset({"string"}), "'+' on text", start_column(node.right))
                return "string"
            self.need(left, frozenset({"number"}), f"'{node.op}'", start_column(node.left))
            self.need(right, frozenset({"number"}), f"'{node.op}'", start_column(node.right))
            return "number"
        if isinstance(node, Compare):
            self.compare(node, self.kind(node.left), self.kind(node.right))
            return "bool"
        if isinstance(node, Logic):
            self.need(self.kind(node.left), frozenset({"bool"}), f"'{node.op}'", start_column(node.left))
            self.need(self.kind(node.right), frozenset({"bool"}), f"'{node.op}'", start_column(node.right))
            return "bool"
        if isinstance(node, In):
            self.need(
                self.kind(node.operand),
                frozenset({"number", "string", "bool"}),
                "'in'",
                start_column(node.operand),
            )
            return "bool"
        if isinstance(node, Quantifier):
            return self.quantifier(node)
        return self.call(node)

    def compare(self, node: Compare, left: str, right: str) -> None:
        allowed = SCALARS if node.op in ("==", "!=") else frozenset({"number", "string"})
        self.need(left, allowed, f"'{node.op}'", start_column(node.left))
        self.need(right, allowed, f"'{node.op}'", start_column(node.right))
        if "unknown" not in (left, right) and left != right:
            raise self.fail(f"cannot compare {left} with {right}", node.column)

    def quantifier(self, node: Quantifier) -> str:
        test = node.test
        left, right = self.kind(test.left), self.kind(test.right)
        where = start_column(test)
        if left in SEQUENCES and right in SEQUENCES:
            raise self.fail(f"{node.name}() needs an array on one side only", where)
        if left not in SEQUENCES | {"unknown"} and right not in SEQUENCES | {"unknown"}:
            raise self.fail(f"{node.name}() needs an array on one side of the comparison", where)
        self.compare(test, self.element(test.left, left), self.element(test.right, right))
        return "bool"

    def element(self, side: Node, kind: str) -> str:
        """The kind of the elements of an array operand (``kind`` itself for a scalar)."""
        if kind == "bytes":
            return "number"
        if kind == "array" and isinstance(side, Field) and self.field_kind is not None:
            return self.field_kind((*side.steps, 0))
        return "unknown" if kind == "array" else kind

    def call(self, node: Call) -> str:
        kinds = [self.kind(arg) for arg in node.args]
        name = node.name
        if name in ("abs", "sqrt"):
            self.need(kinds[0], frozenset({"number"}), f"{name}()", node.column)
            return "number"
        if name in ("isnan", "isfinite"):
            self.need(kinds[0], frozenset({"number"}), f"{name}()", node.column)
            return "bool"
        if name in ("len", "size"):
            self.need(kinds[0], frozenset({"string", "bytes", "array", "map"}), f"{name}()", node.column)
            return "number"
        # min / max: one array, or several numbers
        if len(kinds) == 1:
            self.need(kinds[0], frozenset({"array", "bytes"}), f"{name}() of one argument", node.column)
        else:
            for kind in kinds:
                self.need(kind, frozenset({"number"}), f"{name}()", node.column)
        return "number"


def start_column(node: Node) -> int:
    """The column where the source text of ``node`` begins."""
    if isinstance(node, Arith | Compare | Logic):
        return start_column(node.left)
    if isinstance(node, In):
        return start_column(node.operand)
    return node.column


def check_expression(node: Node, source: str, field_kind: FieldKind | None = None) -> str:
    """The kind ``node`` evaluates to; raises ``ExpressionError`` for misuse (with its column)."""
    return _Checker(source, field_kind).kind(node)


def check_predicate(node: Node, source: str, field_kind: FieldKind | None = None) -> None:
    """Check that ``node`` is a well-formed condition (evaluates to a bool)."""
    kind = check_expression(node, source, field_kind)
    if kind not in ("bool", "unknown"):
        raise ExpressionError(
            f"a filter must be a condition (true/false), this is a {kind}",
            expression=source,
            column=start_column(node),
        )
