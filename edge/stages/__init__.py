"""Pure, clock-injected pipeline stages run per mapping on decoded messages.

``filter``, ``throttle``, ``on_change``, ``project``, ``aggregate`` and ``compress_image``,
declared in config as a list of ``StageSpec`` and built with ``build_pipeline``. See
docs/stages.md and docs/images.md.
"""

from fleetlink.common.durations import DurationNs, format_duration, parse_duration
from fleetlink.edge.stages.aggregate import AggregateStage
from fleetlink.edge.stages.base import Sample, Stage, StageCounters
from fleetlink.edge.stages.compress_image import CompressImageStage
from fleetlink.edge.stages.errors import EvaluationError, ExpressionError, FieldPathError, StageConfigError
from fleetlink.edge.stages.filter import FilterStage
from fleetlink.edge.stages.on_change import OnChangeStage
from fleetlink.edge.stages.pipeline import Pipeline, build_pipeline, build_stage
from fleetlink.edge.stages.project import ProjectStage
from fleetlink.edge.stages.spec import (
    AggregateSpec,
    CompressImageSpec,
    FilterSpec,
    OnChangeSpec,
    ProjectSpec,
    StageSpec,
    ThrottleSpec,
)
from fleetlink.edge.stages.throttle import ThrottleStage

__all__ = [
    "AggregateSpec",
    "AggregateStage",
    "CompressImageSpec",
    "CompressImageStage",
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
