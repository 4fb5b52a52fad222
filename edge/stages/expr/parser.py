"""Recursive-descent parser: tokens -> syntax tree (see docs/stages.md for the grammar).

Precedence, lowest first: ``||``, ``&&``, comparisons and ``in`` (not chainable), ``+ -``,
``* / %``, unary ``! -``, method calls ``x.size()``.
"""

from __future__ import annotations

from fleetlink.edge.stages.errors import ExpressionError
from fleetlink.edge.stages.expr.lexer import Token, tokenize
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
from fleetlink.edge.stages.paths import Step

MAX_DEPTH = 64
"""Deepest syntax tree accepted: keeps parsing, checking and evaluation far from Python's
recursion limit whatever the text (``1+1+...+1`` is as deep as it is long)."""
COMPARISONS = frozenset({"==", "!=", "<", "<=", ">", ">="})
META_NAMES = frozenset({"robot", "topic", "stamp_ns"})
# name -> (min args, max args or None for any number)
FUNCTIONS: dict[str, tuple[int, int | None]] = {
    "abs": (1, 1),
    "len": (1, 1),
    "size": (1, 1),
    "min": (1, None),
    "max": (1, None),
    "sqrt": (1, 1),
    "isnan": (1, 1),
    "isfinite": (1, 1),
    "any": (1, 1),
    "all": (1, 1),
}


class _Parser:
    def __init__(self, source: str) -> None:
        self.source = source
        self.tokens = tokenize(source)
        self.pos = 0
        self.nesting = 0

    @property
    def tok(self) -> Token:
        return self.tokens[self.pos]

    def fail(self, reason: str, token: Token | None = None) -> ExpressionError:
        token = token or self.tok
        return ExpressionError(reason, expression=self.source, column=token.column)

    def found(self) -> str:
        return "end of expression" if self.tok.kind == "end" else repr(self.tok.text)

    def at_end(self) -> bool:
        return self.tok.kind == "end"

    def at(self, *ops: str) -> bool:
        return self.tok.kind == "op" and self.tok.text in ops

    def take(self) -> Token:
        token = self.tok
        self.pos += 1
        return token

    def expect(self, op: str) -> Token:
        if not self.at(op):
            raise self.fail(f"expected {op!r}, found {self.found()}")
        return self.take()

    def parse(self) -> Node:
        if self.at_end():
            raise self.fail("empty expression")
        node = self.or_expr()
        if not self.at_end():
            raise self.fail(f"unexpected {self.found()} after a complete expression")
        return node

    def or_expr(self) -> Node:
        node = self.and_expr()
        while self.at("||"):
            token = self.take()
            node = Logic("||", node, self.and_expr(), token.column)
        return node

    def and_expr(self) -> Node:
        node = self.relation()
        while self.at("&&"):
            token = self.take()
            node = Logic("&&", node, self.relation(), token.column)
        return node

    def relation(self) -> Node:
        node = self.sum()
        if self.at(*COMPARISONS):
            token = self.take()
            node = Compare(token.text, node, self.sum(), token.column)
        elif self.at("in"):
            token = self.take()
            node = In(node, self.const_list(), token.column)
        if self.at(*COMPARISONS, "in"):
            raise self.fail("comparisons cannot be chained; combine them with && or ||")
        return node

    def const_list(self) -> tuple[Const, ...]:
        self.expect("[")
        items: list[Const] = []
        while not self.at("]"):
            item = self.unary()
            if not isinstance(item, Const):
                raise ExpressionError(
                    "'in [...]' takes literal values only", expression=self.source, column=_column(item)
                )
            items.append(item)
            if not self.at("]"):
                self.expect(",")
        self.take()
        return tuple(items)

    def sum(self) -> Node:
        node = self.product()
        while self.at("+", "-"):
            token = self.take()
            node = Arith(token.text, node, self.product(), token.column)
        return node

    def product(self) -> Node:
        node = self.unary()
        while self.at("*", "/", "%"):
            token = self.take()
            node = Arith(token.text, node, self.unary(), token.column)
        return node

    def nest(self, token: Token) -> None:
        self.nesting += 1
        if self.nesting > MAX_DEPTH:
            raise self.fail(f"expression is nested too deeply (more than {MAX_DEPTH} levels)", token)

    def unary(self) -> Node:
        if self.at("!", "-"):
            token = self.take()
            self.nest(token)
            operand = self.unary()
            self.nesting -= 1
            if token.text == "-" and isinstance(operand, Const):
                value = operand.value
                if isinstance(value, int | float) and not isinstance(value, bool):
                    return Const(-value, token.column)
            return Unary(token.text, operand, token.column)
        return self.postfix()

    def postfix(self) -> Node:
        node = self.primary()
        while self.at("."):
            dot = self.take()
            if self.tok.kind != "ident":
                raise self.fail(f"expected a method name after '.', found {self.found()}")
            name = self.take()
            if not self.at("("):
                raise self.fail("field access is only allowed on field paths", dot)
            node = self.call(name, (node,))
        return node

    def primary(self) -> Node:
        token = self.tok
        if token.kind in ("num", "str"):
            self.take()
            if token.value is None:  # pragma: no cover - the lexer always sets a value here
                raise self.fail("literal without a value", token)
            return Const(token.value, token.column)
        if self.at("true", "false"):
            self.take()
            return Const(token.text == "true", token.column)
        if token.kind == "meta":
            if token.text not in META_NAMES:
                raise self.fail(f"unknown name @{token.text} (use @robot, @topic or @stamp_ns)")
            self.take()
            return Meta(token.text, token.column)
        if self.at("("):
            self.nest(self.take())
            node = self.or_expr()
            self.expect(")")
            self.nesting -= 1
            return node
        if token.kind == "ident":
            self.take()
            if self.at("("):
                return self.call(token, ())
            return self.path(token)
        raise self.fail(f"expected a value, a field or '(', found {self.found()}")

    def path(self, first: Token) -> Node:
        steps: list[Step] = [first.text]
        while True:
            if (
                self.at(".")
                and self.tokens[self.pos + 1].kind == "ident"
                and not (self.tokens[self.pos + 2].kind == "op" and self.tokens[self.pos + 2].text == "(")
            ):
                self.take()
                steps.append(self.take().text)
            elif self.at("["):
                self.take()
                negative = self.at("-")
                if negative:
                    self.take()
                index = self.tok.value
                if self.tok.kind != "num" or not isinstance(index, int):
                    raise self.fail(f"expected an integer index, found {self.found()}")
                self.take()
                steps.append(-index if negative else index)
                self.expect("]")
            else:
                return Field(tuple(steps), first.column)

    def call(self, name: Token, receiver: tuple[Node, ...]) -> Node:
        arity = FUNCTIONS.get(name.text)
        if arity is None:
            known = ", ".join(sorted(FUNCTIONS))
            raise self.fail(f"unknown function {name.text!r} (known: {known})", name)
        self.nest(self.expect("("))
        args = list(receiver)
        while not self.at(")"):
            args.append(self.or_expr())
            if not self.at(")"):
                self.expect(",")
        self.take()
        self.nesting -= 1
        low, high = arity
        if len(args) < low or (high is not None and len(args) > high):
            wanted = f"{low}" if low == high else f"at least {low}"
            raise self.fail(f"{name.text}() takes {wanted} argument(s), got {len(args)}", name)
        if name.text in ("any", "all"):
            test = args[0]
            if not isinstance(test, Compare):
                raise ExpressionError(
                    f"{name.text}() takes a comparison with an array on one side, e.g. "
                    f"{name.text}(ranges < 0.5)",
                    expression=self.source,
                    column=_column(test),
                )
            return Quantifier(name.text, test, name.column)
        return Call(name.text, tuple(args), name.column)


def _column(node: Node) -> int:
    return node.column


def _children(node: Node) -> tuple[Node, ...]:
    if isinstance(node, Unary):
        return (node.operand,)
    if isinstance(node, Arith | Compare | Logic):
        return (node.left, node.right)
    if isinstance(node, In):
        return (node.operand,)
    if isinstance(node, Call):
        return node.args
    if isinstance(node, Quantifier):
        return (node.test,)
    return ()


def _check_depth(root: Node, source: str) -> None:
    stack = [(root, 1)]
    while stack:
        node, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise ExpressionError(
                f"expression is nested too deeply (more than {MAX_DEPTH} levels)",
                expression=source,
                column=node.column,
            )
        stack.extend((child, depth + 1) for child in _children(node))


def parse_expression(source: str) -> Node:
    """Parse ``source``; raises ``ExpressionError`` with the column of the first problem."""
    node = _Parser(source).parse()
    _check_depth(node, source)
    return node
