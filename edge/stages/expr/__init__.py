"""The filter expression language: tokenizer, parser, static checker, closure compiler.

No ``eval``/``exec``: user text only ever becomes a syntax tree of known node types.
The language is described in docs/stages.md.
"""

from fleetlink.edge.stages.expr.checker import check_expression, check_predicate
from fleetlink.edge.stages.expr.compiler import compile_predicate
from fleetlink.edge.stages.expr.parser import FUNCTIONS, parse_expression

__all__ = ["FUNCTIONS", "check_expression", "check_predicate", "compile_predicate", "parse_expression"]
