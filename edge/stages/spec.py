"""The YAML/JSON shape of stages: ``StageSpec``, a union discriminated by ``type``.

Each model checks what it can without the message type (expression syntax, path syntax, option
ranges); field existence is checked against the Avro schema when the pipeline is built for a
topic (``Pipeline.output_schema``).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import ConfigDict, Field, field_validator, model_validator

from fleetlink.common.configfile import Section
from fleetlink.common.durations import DurationNs
from fleetlink.common.names import KeyChunk
from fleetlink.edge.stages.errors import StageConfigError
from fleetlink.edge.stages.expr import check_predicate, parse_expression
from fleetlink.edge.stages.paths import parse_path

Op = Literal["count", "mean", "min", "max", "last", "stddev"]
FieldPaths = Annotated[list[str], Field(min_length=1)]


class _Spec(Section):
    model_config = ConfigDict(strict=True, frozen=True)

    name: KeyChunk | None = None
    """Label for metrics and the admin API; defaults to the stage type."""


def _check_paths(paths: list[str]) -> list[str]:
    for path in paths:
        try:
            parse_path(path)
        except StageConfigError as exc:
            raise ValueError(str(exc)) from None
    if len(set(paths)) != len(paths):
        raise ValueError(f"a field is listed more than once: {paths}")
    return paths


class FilterSpec(_Spec):
    """Forward a sample only when an expression on its fields holds."""

    type: Literal["filter"]
    expr: Annotated[str, Field(min_length=1, max_length=4096)]

    @field_validator("expr")
    @classmethod
    def _parses(cls, expr: str) -> str:
        try:
            check_predicate(parse_expression(expr), expr)
        except StageConfigError as exc:
            raise ValueError(f"invalid filter expression: {exc}") from None
        return expr


class ThrottleSpec(_Spec):
    """At most ``hz`` samples per second per robot and topic."""

    type: Literal["throttle"]
    hz: Annotated[float, Field(gt=0, le=1_000_000)]
    keep: Literal["latest", "first"] = "latest"


class OnChangeSpec(_Spec):
    """Forward a sample only when one of the fields changed."""

    type: Literal["on_change"]
    fields: FieldPaths
    deadband: Annotated[float, Field(ge=0, allow_inf_nan=False)] = 0.0
    heartbeat: DurationNs | None = None

    _paths = field_validator("fields")(_check_paths)

    @field_validator("heartbeat")
    @classmethod
    def _positive(cls, value: int | None) -> int | None:
        if value is not None and value <= 0:
            raise ValueError("heartbeat must be longer than 0s")
        return value


class ProjectSpec(_Spec):
    """Keep only the chosen fields."""

    type: Literal["project"]
    fields: FieldPaths
    flatten: bool = False

    _paths = field_validator("fields")(_check_paths)


class AggregateSpec(_Spec):
    """Event-time windows per robot and topic over numeric fields."""

    type: Literal["aggregate"]
    window: DurationNs
    hop: DurationNs | None = None
    fields: FieldPaths
    ops: Annotated[list[Op], Field(min_length=1)]
    allowed_lateness: DurationNs = 0
    idle_timeout: DurationNs | None = None

    _paths = field_validator("fields")(_check_paths)

    @field_validator("ops")
    @classmethod
    def _distinct(cls, ops: list[Op]) -> list[Op]:
        if len(set(ops)) != len(ops):
            raise ValueError(f"an op is listed more than once: {ops}")
        return ops

    @model_validator(mode="after")
    def _windows(self) -> AggregateSpec:
        if self.window <= 0:
            raise ValueError("window must be longer than 0s")
        if self.hop is not None and not 0 < self.hop <= self.window:
            raise ValueError("hop must be longer than 0s and at most the window")
        if self.idle_timeout is not None and self.idle_timeout <= 0:
            raise ValueError("idle_timeout must be longer than 0s")
        return self


class CompressImageSpec(_Spec):
    """sensor_msgs/Image -> sensor_msgs/CompressedImage (docs/images.md)."""

    type: Literal["compress_image"]
    format: Literal["jpeg", "png"] = "jpeg"
    quality: Annotated[int, Field(ge=1, le=100)] = 80
    """JPEG quality (1-100; libjpeg's scale: 75-90 for camera images)."""
    level: Annotated[int, Field(ge=0, le=9)] = 1
    """PNG zlib level (0-9; 1 is fast and nearly as small as 6 on camera images)."""


StageSpec = Annotated[
    FilterSpec | ThrottleSpec | OnChangeSpec | ProjectSpec | AggregateSpec | CompressImageSpec,
    Field(discriminator="type"),
]
"""One entry of a mapping's ``stages:`` list."""
