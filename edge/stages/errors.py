"""Errors raised by the edge pipeline stages.

Configuration problems (a bad expression, a field path that the message type does not have,
an unusable stage option) are ``StageConfigError``: a ``fleetlink.common.errors.ConfigError``, so the
config loader and the admin API report them like any other config mistake. Per-sample problems
never raise out of ``Stage.process``: they are counted (``errors``) and the sample is dropped.
"""

from __future__ import annotations

from fleetlink.common.errors import ConfigError
from fleetlink.edge.errors import EdgeError


class StageConfigError(ConfigError, EdgeError):
    """A stage cannot be built, or does not fit the message type it is applied to."""

    def in_context(self, prefix: str) -> StageConfigError:
        """The same error (same class and attributes) with ``prefix: `` before its message."""
        clone = type(self).__new__(type(self))
        clone.__dict__.update(self.__dict__)
        clone.args = (f"{prefix}: {self}",)
        return clone


class FieldPathError(StageConfigError):
    """A field path is malformed, or does not exist in the message type (Avro schema)."""

    def __init__(self, message: str, *, path: str, type_name: str | None = None) -> None:
        super().__init__(message)
        self.path = path
        self.type_name = type_name


class ExpressionError(StageConfigError):
    """A filter expression does not parse, or does not fit the message type.

    ``column`` is 1-based and points into ``expression``; ``str()`` shows a caret under it.
    """

    def __init__(self, reason: str, *, expression: str, column: int) -> None:
        self.reason = reason
        self.expression = expression
        self.column = column
        caret = " " * (column - 1) + "^"
        super().__init__(f"column {column}: {reason}\n  {expression}\n  {caret}")


class EvaluationError(Exception):
    """Raised inside a compiled expression for one sample; caught and counted by the filter stage.

    Not a ``FleetlinkError`` on purpose: it never leaves ``Stage.process``.
    """
