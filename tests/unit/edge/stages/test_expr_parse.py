"""Expression syntax: what parses to what, and parse errors with their column."""

from __future__ import annotations

import pytest

from fleetlink.edge.stages.errors import ExpressionError
from fleetlink.edge.stages.expr import check_predicate, parse_expression
from fleetlink.edge.stages.expr.nodes import (
    Arith,
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


def show(node: Node) -> str:
    """A fully parenthesised rendering, to state precedence in the table below."""
    if isinstance(node, Const):
        return repr(node.value)
    if isinstance(node, Field):
        return "$" + ".".join(str(s) for s in node.steps)
    if isinstance(node, Meta):
        return "@" + node.name
    if isinstance(node, Unary):
        return f"({node.op}{show(node.operand)})"
    if isinstance(node, Arith | Compare | Logic):
        return f"({show(node.left)} {node.op} {show(node.right)})"
    if isinstance(node, In):
        return f"({show(node.operand)} in [{', '.join(show(o) for o in node.options)}])"
    if isinstance(node, Quantifier):
        return f"{node.name}{show(node.test)}"
    return f"{node.name}({', '.join(show(a) for a in node.args)})"


@pytest.mark.parametrize(
    ("source", "tree"),
    [
        (
            "kidnap.is_kidnapped == true || data.size() > 3",
            "(($kidnap.is_kidnapped == True) || (size($data) > 3))",
        ),
        ("a || b && c", "($a || ($b && $c))"),
        ("a && b || c", "(($a && $b) || $c)"),
        ("1 + 2 * 3 > 6", "((1 + (2 * 3)) > 6)"),
        ("(1 + 2) * 3 == 9", "(((1 + 2) * 3) == 9)"),
        ("10 - 4 - 3 == 3", "(((10 - 4) - 3) == 3)"),
        ("!a && !!b", "((!$a) && (!(!$b)))"),
        ("-x < -2.5", "((-$x) < -2.5)"),
        ("x % 2 == 1", "(($x % 2) == 1)"),
        ("ranges[0] <= 1e-3", "($ranges.0 <= 0.001)"),
        ("ranges[-1] >= .5", "($ranges.-1 >= 0.5)"),
        ("a.b[2].c != 'it''s'", None),  # two strings in a row: an error, see below
        ("@robot in ['tb4_01', \"tb4_02\"]", "(@robot in ['tb4_01', 'tb4_02'])"),
        ("level in [1, -2, 3.5, true]", "($level in [1, -2, 3.5, True])"),
        ("any(ranges < 0.2)", "any($ranges < 0.2)"),
        ("all(0 < ranges)", "all(0 < $ranges)"),
        ("max(a, b, 3) >= abs(c)", "(max($a, $b, 3) >= abs($c))"),
        ("x.abs() > 1", "(abs($x) > 1)"),
        ("size.size() > 1", "(size($size) > 1)"),  # a field called like a function
        ("'a\\'b\\n' == s", '("a\'b\\n" == $s)'),
        ("@stamp_ns % 1000 == 0 && @topic == '/x'", "(((@stamp_ns % 1000) == 0) && (@topic == '/x'))"),
    ],
)
def test_parses(source: str, tree: str | None) -> None:
    if tree is None:
        with pytest.raises(ExpressionError):
            parse_expression(source)
        return
    assert show(parse_expression(source)) == tree


@pytest.mark.parametrize(
    ("source", "column", "reason"),
    [
        ("", 1, "empty expression"),
        ("a ==", 5, "expected a value, a field or '(', found end of expression"),
        ("a = 1", 3, "unexpected character '=' (use == to compare)"),
        ("a & b", 3, "use && or ||"),
        ("(a > 1", 7, "expected ')', found end of expression"),
        ("a > 1)", 6, "unexpected ')' after a complete expression"),
        ("foo(1) > 0", 1, "unknown function 'foo'"),
        ("1 < x < 3", 7, "comparisons cannot be chained"),
        ("'open", 1, "string is not closed"),
        ("'bad \\q'", 6, "unknown escape \\q"),
        ("x[a] > 1", 3, "expected an integer index, found 'a'"),
        ("x[1.5] > 1", 3, "expected an integer index"),
        ("x.1 > 0", 2, "unexpected '.1' after a complete expression"),
        ("x.(1) > 0", 3, "expected a method name after '.', found '('"),
        ("(x).y > 0", 4, "field access is only allowed on field paths"),
        ("@who == 'a'", 1, "unknown name @who"),
        ("@ == 'a'", 1, "expected a name after '@'"),
        ("12ab > 1", 1, "invalid number '12a'"),
        ("abs(1, 2) > 0", 1, "abs() takes 1 argument(s), got 2"),
        ("min() > 0", 1, "min() takes at least 1 argument(s), got 0"),
        ("any(ranges) ", 5, "any() takes a comparison"),
        ("x in [y]", 7, "'in [...]' takes literal values only"),
        ("x in 3", 6, "expected '['"),
        ("x # 1", 3, "unexpected character '#'"),
        ("a && 1", 6, "'&&' needs bool, got number"),
        ("!3", 2, "'!' needs bool, got number"),
        ("'a' - 1 > 0", 1, "'-' needs number, got string"),
        ("'a' + 1 == 'a1'", 7, "'+' on text needs string, got number"),
        ("1 == 'a'", 3, "cannot compare number with string"),
        ("true < false", 1, "'<' needs number or string, got bool"),
        ("x + 1", 1, "a filter must be a condition (true/false), this is a number"),
        ("len(3) > 1", 1, "len() needs array or bytes or map or string, got number"),
        ("isnan('x')", 1, "isnan() needs number, got string"),
        ("any(1 < 2)", 5, "any() needs an array on one side"),
    ],
)
def test_errors_give_the_column(source: str, column: int, reason: str) -> None:
    with pytest.raises(ExpressionError) as info:
        check_predicate(parse_expression(source), source)
    err = info.value
    assert err.column == column, str(err)
    assert reason in err.reason
    assert str(err).startswith(f"column {column}: ")
    lines = str(err).splitlines()
    assert lines[1] == f"  {source}"
    assert lines[2] == "  " + " " * (column - 1) + "^"


@pytest.mark.parametrize(
    "source",
    ["x", "kidnap.is_kidnapped", "x > 1 && y", "isnan(x)", "!flag", "x == y", "a.b + 1 > c * 2"],
)
def test_fields_of_unknown_kind_pass_without_a_schema(source: str) -> None:
    check_predicate(parse_expression(source), source)


@pytest.mark.parametrize(
    "source",
    [
        "(" * 70 + "x" + ")" * 70 + " > 1",
        "!" * 70 + "x",
        " + ".join(["1"] * 70) + " > 1",
        " && ".join(["x"] * 70),
        "-" * 70 + "x > 1",
        "max(" * 70 + "1" + ")" * 70 + " > 0",
        "(" * 1000 + "x",
        "max(" * 900,
        "!" * 4000,
    ],
)
def test_deep_nesting_is_refused_not_a_recursion_error(source: str) -> None:
    with pytest.raises(ExpressionError, match="nested too deeply"):
        parse_expression(source)


def test_moderate_nesting_is_fine() -> None:
    source = " + ".join(["x"] * 40) + " > 1"
    assert parse_expression(source) is not None
