"""Pure, clock-injected pipeline stages run per mapping on decoded messages.

``filter``, ``throttle``, ``on_change``, ``project`` and ``aggregate``, declared in config as a
list of ``StageSpec`` and built with ``build_pipeline``. See docs/stages.md.
"""

from edge.stages.aggregate import AggregateStage
from edge.stages.base import Sample, Stage, StageCounters
from edge.stages.errors import EvaluationError, ExpressionError, FieldPathError, StageConfigError
from edge.stages.filter import FilterStage
from edge.stages.on_change import OnChangeStage
from edge.stages.pipeline import Pipeline, build_pipeline, build_stage
from edge.stages.project import ProjectStage
from edge.stages.spec import (
    AggregateSpec,
    FilterSpec,
    OnChangeSpec,
    ProjectSpec,
    StageSpec,
    ThrottleSpec,
)
from edge.stages.throttle import ThrottleStage
from fleetlink.durations import DurationNs, format_duration, parse_duration

__all__ = [
    "AggregateSpec",
    "AggregateStage",
    "DurationNs",
    "EvaluationError",
    "ExpressionError",
    "FieldPathError",
    "FilterSpec",
    "FilterStage",
    "OnChangeSpec",
    "OnChangeStage",
    "Pipeline",
    "ProjectSpec",
    "ProjectStage",
    "Sample",
    "Stage",
    "StageConfigError",
    "StageCounters",
    "StageSpec",
    "ThrottleSpec",
    "ThrottleStage",
    "build_pipeline",
    "build_stage",
    "format_duration",
    "parse_duration",
]
