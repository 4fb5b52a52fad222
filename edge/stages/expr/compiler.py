"""Syntax tree -> a tree of closures, built once per filter. Evaluating one sample is a few
nested Python calls with fast paths for numbers; kind mismatches, missing fields and bad indexes
raise (``EvaluationError``, ``LookupError``, ``TypeError``) for the stage to count.

Values are typed as in the decoded message: number (int/float, never bool), string, bool,
bytes, array (list, tuple, numpy array), record (mapping). numpy scalars count as numbers/bools.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from fleetlink.edge.stages.base import Sample
from fleetlink.edge.stages.errors import EvaluationError
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
from fleetlink.edge.stages.paths import Steps, make_getter, plain

Fn = Callable[[Sample], Any]

_COMPARE: dict[str, Callable[[Any, Any], Any]] = {
    "==": operator.eq,
    "!=": operator.ne,
    "<": operator.lt,
    "<=": operator.le,
    ">": operator.gt,
    ">=": operator.ge,
}
_ORDERED = frozenset({"number", "string"})
_EQUATABLE = frozenset({"number", "string", "bool", "bytes"})


def runtime_kind(value: Any) -> str:  # noqa: PLR0911 - one return per kind
    """The kind of a decoded message value (``number``, ``string``, ``array``, ...) for checks and errors."""
    value = plain(value)
    if type(value) is bool:
        return "bool"
    if isinstance(value, int | float):
        return "number"
    if isinstance(value, str):
        return "string"
    if isinstance(value, bytes | bytearray):
        return "bytes"
    if isinstance(value, list | tuple | np.ndarray):
        return "array"
    if isinstance(value, Mapping):
        return "record"
    return "null" if value is None else type(value).__name__


def _is_number(value: Any) -> bool:
    return type(value) is float or type(value) is int


def as_bool(value: Any) -> bool:
    """``value`` if it is a bool; raises ``EvaluationError`` otherwise."""
    value = plain(value)
    if type(value) is bool:
        return value
    raise EvaluationError(f"expected a bool, got {runtime_kind(value)}")


def as_number(value: Any, what: str) -> int | float:
    """``value`` if it is a number; raises ``EvaluationError`` naming ``what`` otherwise."""
    value = plain(value)
    if type(value) is float or type(value) is int:
        return value
    raise EvaluationError(f"{what} needs a number, got {runtime_kind(value)}")


def _compare_slow(op: str, a: Any, b: Any) -> bool:
    a, b = plain(a), plain(b)
    kind_a, kind_b = runtime_kind(a), runtime_kind(b)
    allowed = _EQUATABLE if op in ("==", "!=") else _ORDERED
    if kind_a != kind_b or kind_a not in allowed:
        raise EvaluationError(f"cannot compare {kind_a} {op} {kind_b}")
    return bool(_COMPARE[op](a, b))


def _field(steps: Steps) -> Fn:
    keys = [step for step in steps if isinstance(step, str)]
    if len(keys) == len(steps):
        if len(keys) == 1:
            (a,) = keys
            return lambda s: s.value[a]
        if len(keys) == 2:
            a, b = keys
            return lambda s: s.value[a][b]
        if len(keys) == 3:
            a, b, c = keys
            return lambda s: s.value[a][b][c]
    get = make_getter(steps)
    return lambda s: get(s.value)


def _compare(node: Compare) -> Fn:
    op_text = node.op
    op = _COMPARE[op_text]
    left = compile_node(node.left)
    right_node = node.right
    if isinstance(right_node, Const) and _is_number(right_node.value):
        const = right_node.value

        def compare_number(s: Sample) -> Any:
            a = left(s)
            if type(a) is float or type(a) is int:
                return op(a, const)
            return _compare_slow(op_text, a, const)

        return compare_number
    right = compile_node(right_node)

    def compare(s: Sample) -> Any:
        a = left(s)
        b = right(s)
        if (type(a) is float or type(a) is int) and (type(b) is float or type(b) is int):
            return op(a, b)
        if type(a) is str and type(b) is str:
            return op(a, b)
        return _compare_slow(op_text, a, b)

    return compare


def _divide(a: int | float, b: int | float) -> float:
    if b == 0:
        raise EvaluationError("division by zero")
    return a / b


def _modulo(a: int | float, b: int | float) -> int | float:
    if b == 0:
        raise EvaluationError("modulo by zero")
    return a % b


_ARITH: dict[str, Callable[[Any, Any], Any]] = {
    "+": operator.add,
    "-": operator.sub,
    "*": operator.mul,
    "/": _divide,
    "%": _modulo,
}


def _arith(node: Arith) -> Fn:
    op_text = node.op
    op = _ARITH[op_text]
    left, right = compile_node(node.left), compile_node(node.right)

    def arith(s: Sample) -> Any:
        a = left(s)
        b = right(s)
        if (type(a) is float or type(a) is int) and (type(b) is float or type(b) is int):
            return op(a, b)
        a, b = plain(a), plain(b)
        if op_text == "+" and type(a) is str and type(b) is str:
            return a + b
        return op(as_number(a, f"'{op_text}'"), as_number(b, f"'{op_text}'"))

    return arith


def _logic(node: Logic) -> Fn:
    left, right = compile_node(node.left), compile_node(node.right)
    if node.op == "||":

        def either(s: Sample) -> bool:
            a = left(s)
            if a is True or (a is not False and as_bool(a)):
                return True
            b = right(s)
            return b if b is True or b is False else as_bool(b)

        return either

    def both(s: Sample) -> bool:
        a = left(s)
        if a is False or (a is not True and not as_bool(a)):
            return False
        b = right(s)
        return b if b is True or b is False else as_bool(b)

    return both


def _unary(node: Unary) -> Fn:
    operand = compile_node(node.operand)
    if node.op == "!":

        def negate(s: Sample) -> bool:
            a = operand(s)
            if a is True:
                return False
            if a is False:
                return True
            return not as_bool(a)

        return negate
    return lambda s: -as_number(operand(s), "unary '-'")


def _in(node: In) -> Fn:
    operand = compile_node(node.operand)
    numbers = frozenset(c.value for c in node.options if _is_number(c.value))
    texts = frozenset(c.value for c in node.options if type(c.value) is str)
    flags = frozenset(c.value for c in node.options if type(c.value) is bool)

    def member(s: Sample) -> bool:
        a = plain(operand(s))
        if type(a) is str:
            return a in texts
        if type(a) is bool:
            return a in flags
        if type(a) is float or type(a) is int:
            return a in numbers
        raise EvaluationError(f"'in' needs a number, string or bool, got {runtime_kind(a)}")

    return member


def _is_sequence(value: Any) -> bool:
    return isinstance(value, list | tuple | np.ndarray | bytes | bytearray)


def _quantifier(node: Quantifier) -> Fn:
    test = node.test
    op_text = test.op
    op = _COMPARE[op_text]
    left, right = compile_node(test.left), compile_node(test.right)
    reduce_any = node.name == "any"

    def quantify(s: Sample) -> bool:
        a, b = left(s), right(s)
        if _is_sequence(a) and not _is_sequence(b):
            items, scalar, flipped = a, plain(b), False
        elif _is_sequence(b) and not _is_sequence(a):
            items, scalar, flipped = b, plain(a), True
        else:
            raise EvaluationError(f"{node.name}() needs an array on exactly one side of {op_text}")
        if isinstance(items, np.ndarray) and items.dtype.kind in "iuf" and _is_number(scalar):
            result = op(scalar, items) if flipped else op(items, scalar)
            return bool(result.any() if reduce_any else result.all())
        for item in items:
            hit = _compare_slow(op_text, scalar, item) if flipped else _compare_slow(op_text, item, scalar)
            if hit is reduce_any:
                return reduce_any
        return not reduce_any

    return quantify


def _length(value: Any) -> int:
    if isinstance(value, str | bytes | bytearray | list | tuple | np.ndarray | Mapping):
        return len(value)
    raise EvaluationError(f"len()/size() needs text, bytes, an array or a map, got {runtime_kind(value)}")


def _extreme(name: str, args: list[Any]) -> int | float:
    pick = min if name == "min" else max
    if len(args) == 1:
        items = args[0]
        if isinstance(items, np.ndarray) and items.dtype.kind in "iuf":
            if items.size == 0:
                raise EvaluationError(f"{name}() of an empty array")
            return plain(items.min() if name == "min" else items.max())  # type: ignore[no-any-return]
        if not _is_sequence(items):
            raise EvaluationError(f"{name}() of one argument needs an array, got {runtime_kind(items)}")
        if len(items) == 0:
            raise EvaluationError(f"{name}() of an empty array")
        return pick(as_number(item, f"{name}()") for item in items)
    return pick(as_number(arg, f"{name}()") for arg in args)


def _sqrt(value: Any) -> float:
    number = as_number(value, "sqrt()")
    if number < 0:
        raise EvaluationError("sqrt() of a negative number")
    return math.sqrt(number)


_UNARY_FUNCTIONS: dict[str, Callable[[Any], Any]] = {
    "abs": lambda v: abs(as_number(v, "abs()")),
    "sqrt": _sqrt,
    "isnan": lambda v: math.isnan(as_number(v, "isnan()")),
    "isfinite": lambda v: math.isfinite(as_number(v, "isfinite()")),
    "len": _length,
    "size": _length,
}


def _call(node: Call) -> Fn:
    args = [compile_node(arg) for arg in node.args]
    name = node.name
    if name in _UNARY_FUNCTIONS:
        fn = _UNARY_FUNCTIONS[name]
        (arg,) = args
        return lambda s: fn(arg(s))
    return lambda s: _extreme(name, [arg(s) for arg in args])


def compile_node(node: Node) -> Fn:  # noqa: PLR0911 - one branch per node type
    """The closure that evaluates ``node`` on a sample."""
    if isinstance(node, Const):
        value = node.value
        return lambda _s: value
    if isinstance(node, Field):
        return _field(node.steps)
    if isinstance(node, Meta):
        return operator.attrgetter(node.name)
    if isinstance(node, Compare):
        return _compare(node)
    if isinstance(node, Arith):
        return _arith(node)
    if isinstance(node, Logic):
        return _logic(node)
    if isinstance(node, Unary):
        return _unary(node)
    if isinstance(node, In):
        return _in(node)
    if isinstance(node, Quantifier):
        return _quantifier(node)
    return _call(node)


def compile_predicate(node: Node) -> Callable[[Sample], bool]:
    """A function ``sample -> bool``; raises for a sample the expression cannot be evaluated on."""
    fn = compile_node(node)
    if isinstance(node, Compare | Logic | In | Quantifier) or (isinstance(node, Unary) and node.op == "!"):
        return fn

    def predicate(s: Sample) -> bool:
        result = fn(s)
        return result if result is True or result is False else as_bool(result)

    return predicate
