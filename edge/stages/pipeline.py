"""Build stages from their specs and run them in order.

``Pipeline`` is itself a ``Stage``: each output of stage *i* is fed to stage *i+1*; ``tick``
cascades (what stage *i* emits on a tick goes through the stages after it, which then tick
too); ``output_schema`` composes the stages' schemas and is where field paths are checked
against the message type (errors name the stage).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from fleetlink.edge.stages.aggregate import AggregateStage
from fleetlink.edge.stages.base import Sample, Stage, StageCounters
from fleetlink.edge.stages.compress_image import CompressImageStage
from fleetlink.edge.stages.errors import StageConfigError
from fleetlink.edge.stages.filter import FilterStage
from fleetlink.edge.stages.on_change import OnChangeStage
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


def build_stage(spec: StageSpec) -> Stage:
    """A new stage (fresh state and counters) for ``spec``."""
    name = spec.name or spec.type
    if isinstance(spec, FilterSpec):
        return FilterStage(spec.expr, name=name)
    if isinstance(spec, ThrottleSpec):
        return ThrottleStage(spec.hz, spec.keep, name=name)
    if isinstance(spec, OnChangeSpec):
        return OnChangeStage(spec.fields, spec.deadband, spec.heartbeat, name=name)
    if isinstance(spec, ProjectSpec):
        return ProjectStage(spec.fields, flatten=spec.flatten, name=name)
    if isinstance(spec, AggregateSpec):
        return AggregateStage(
            spec.fields,
            spec.ops,
            spec.window,
            hop_ns=spec.hop,
            allowed_lateness_ns=spec.allowed_lateness,
            idle_timeout_ns=spec.idle_timeout,
            name=name,
        )
    if isinstance(spec, CompressImageSpec):
        return CompressImageStage(spec.format, quality=spec.quality, level=spec.level, name=name)
    raise StageConfigError(f"unknown stage spec {spec!r}")  # pragma: no cover - the union is closed


class Pipeline:
    """Stages run in order. ``counters`` counts what entered the first stage (``received``) and
    what left the last one (``emitted``); ``stage_counters()`` has each stage's own."""

    def __init__(self, stages: Sequence[Stage], *, name: str = "pipeline") -> None:
        self.name = name
        self.stages = list(stages)
        self.counters = StageCounters()
        names = [stage.name for stage in self.stages]
        if len(set(names)) != len(names):
            raise StageConfigError(
                f"stage names must be unique within a mapping, got {names} "
                "(give repeated stage types a 'name')"
            )

    def process(self, sample: Sample, now_ns: int) -> list[Sample]:
        """Feed ``sample`` through every stage in order; returns what the last stage emits."""
        self.counters.received += 1
        batch = [sample]
        for stage in self.stages:
            if not batch:
                return []
            if len(batch) == 1:
                batch = stage.process(batch[0], now_ns)
            else:
                batch = [out for item in batch for out in stage.process(item, now_ns)]
        self.counters.emitted += len(batch)
        return batch

    def tick(self, now_ns: int) -> list[Sample]:
        """Tick every stage in order, feeding what a stage emits through the stages after it."""
        carried: list[Sample] = []
        for stage in self.stages:
            out = [result for item in carried for result in stage.process(item, now_ns)]
            out.extend(stage.tick(now_ns))
            carried = out
        self.counters.emitted += len(carried)
        return carried

    def output_schema(self, input_schema: dict[str, Any]) -> dict[str, Any]:
        """The schema of what the last stage emits; raises ``StageConfigError`` naming the stage that does
        not fit."""
        schema = input_schema
        for position, stage in enumerate(self.stages):
            try:
                schema = stage.output_schema(schema)
            except StageConfigError as exc:
                raise exc.in_context(f"stage {position} ({stage.name})") from None
        return schema

    def stage_counters(self) -> dict[str, dict[str, int]]:
        """Each stage's counters, by stage name."""
        return {stage.name: stage.counters.as_dict() for stage in self.stages}

    def totals(self) -> StageCounters:
        """One summary: ``received``/``emitted`` of the whole pipeline, ``passed`` of its last stage,
        ``dropped``, ``late``, ``errors`` and ``nan`` summed over all stages."""
        last = self.stages[-1].counters.passed if self.stages else self.counters.received
        return StageCounters(
            received=self.counters.received,
            passed=last,
            dropped=sum(stage.counters.dropped for stage in self.stages),
            late=sum(stage.counters.late for stage in self.stages),
            errors=sum(stage.counters.errors for stage in self.stages),
            emitted=self.counters.emitted,
            nan=sum(stage.counters.nan for stage in self.stages),
        )


def build_pipeline(specs: Sequence[StageSpec], *, name: str = "pipeline") -> Pipeline:
    """Stages for ``specs`` in order. Unnamed stages are named by type, numbered from the second of
    a type on (``filter``, ``filter_2``); explicit names must be unique."""
    stages = []
    used: set[str] = {spec.name for spec in specs if spec.name is not None}
    for spec in specs:
        stage = build_stage(spec)
        if spec.name is None and stage.name in used:
            number = 2
            while f"{spec.type}_{number}" in used:
                number += 1
            stage.name = f"{spec.type}_{number}"
        used.add(stage.name)
        stages.append(stage)
    return Pipeline(stages, name=name)
