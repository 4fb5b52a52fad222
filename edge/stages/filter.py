"""``filter``: forward a sample only when a condition on its fields holds.

A sample the condition cannot be evaluated on (missing field, index out of range, kind
mismatch, division by zero) is dropped and counted in ``errors``; the first such problem is
logged, later ones only counted; ``last_error`` keeps the most recent message.
"""

from __future__ import annotations

import logging
from typing import Any

from fleetlink.edge.stages.avro import kind_of, resolve_path, root_node
from fleetlink.edge.stages.base import Sample, StageCounters
from fleetlink.edge.stages.errors import EvaluationError
from fleetlink.edge.stages.expr import check_predicate, compile_predicate, parse_expression
from fleetlink.edge.stages.paths import Steps

log = logging.getLogger(__name__)

_SAMPLE_ERRORS = (EvaluationError, LookupError, TypeError, ValueError, ArithmeticError)


class FilterStage:
    """Keeps the samples for which ``expr`` is true."""

    def __init__(self, expr: str, *, name: str = "filter") -> None:
        self.name = name
        self.expr = expr
        self.counters = StageCounters()
        self.last_error: str | None = None
        self._node = parse_expression(expr)
        check_predicate(self._node, expr)
        self._predicate = compile_predicate(self._node)

    def process(self, sample: Sample, now_ns: int) -> list[Sample]:  # noqa: ARG002 - stateless
        """The sample if ``expr`` holds for it, else nothing; a sample it cannot be evaluated on is counted
        as an error and dropped."""
        counters = self.counters
        counters.received += 1
        try:
            keep = self._predicate(sample)
        except _SAMPLE_ERRORS as exc:
            self._record_error(sample, exc)
            return []
        if keep:
            counters.passed += 1
            counters.emitted += 1
            return [sample]
        counters.dropped += 1
        return []

    def tick(self, now_ns: int) -> list[Sample]:  # noqa: ARG002 - nothing is time-driven here
        """Nothing: the stage holds no samples."""
        return []

    def output_schema(self, input_schema: dict[str, Any]) -> dict[str, Any]:
        """Identity; checks every field path and operand kind against ``input_schema``."""
        index, root = root_node(input_schema)

        def field_kind(steps: Steps) -> str:
            return kind_of(resolve_path(index, root, steps))

        check_predicate(self._node, self.expr, field_kind)
        return input_schema

    def _record_error(self, sample: Sample, exc: Exception) -> None:
        self.counters.errors += 1
        message = f"{type(exc).__name__}: {exc}" if not isinstance(exc, EvaluationError) else str(exc)
        if self.last_error is None:
            log.warning(
                "filter cannot evaluate expr=%r robot=%s topic=%s error=%s (further errors are only counted)",
                self.expr,
                sample.robot,
                sample.topic,
                message,
            )
        self.last_error = message
