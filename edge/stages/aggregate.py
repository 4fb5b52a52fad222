"""``aggregate``: event-time windows per (robot, topic) over numeric fields.

Tumbling (``hop == window``) or hopping (``hop < window``) windows aligned on the epoch. Each key
has a watermark = highest source stamp seen - ``allowed_lateness``; a window is emitted once the
watermark reaches its end, or, when the key received nothing for ``idle_timeout`` of processing
time, by ``tick`` (so the last window of a robot that stops is not held forever; its windows
are then closed for good). A sample whose windows are all closed is ``late``: counted, dropped.

Each field statistic skips NaN values (counted in ``counters.nan``); ``<field>_count`` says
how many values were used, the record's ``count`` how many samples fell in the window. A
statistic over no values is null. ``stddev`` is the population standard deviation (ddof 0).
Windows without samples emit nothing.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from fleetlink.edge.stages.avro import kind_of, resolve_path, root_node, short_hash
from fleetlink.edge.stages.base import Sample, StageCounters
from fleetlink.edge.stages.errors import StageConfigError
from fleetlink.edge.stages.paths import Getter, field_name, make_getter, parse_path
from fleetlink.edge.stages.windows import OPS, Window, window_starts

AGG_NAMESPACE = "fleetlink.agg"
_NO_WATERMARK = -(2**63)


class _KeyState:
    __slots__ = ("last_arrival_ns", "max_stamp", "watermark", "windows")

    def __init__(self) -> None:
        self.max_stamp = _NO_WATERMARK
        self.watermark = _NO_WATERMARK
        self.windows: dict[int, Window] = {}
        self.last_arrival_ns = 0


def _number(value: Any) -> float:
    if type(value) is float:
        return float(value)
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | float | np.number):
        raise TypeError(f"aggregate needs numbers, got {type(value).__name__}")
    return float(value)


class AggregateStage:
    """Event-time windows per (robot, topic): emits one record per window with the chosen statistics of
    numeric fields. Durations in nanoseconds."""

    def __init__(
        self,
        fields: Sequence[str],
        ops: Sequence[str],
        window_ns: int,
        *,
        hop_ns: int | None = None,
        allowed_lateness_ns: int = 0,
        idle_timeout_ns: int | None = None,
        name: str = "aggregate",
    ) -> None:
        hop_ns = window_ns if hop_ns is None else hop_ns
        if window_ns <= 0 or hop_ns <= 0 or hop_ns > window_ns:
            raise StageConfigError(
                f"aggregate needs 0 < hop <= window (window={window_ns}ns, hop={hop_ns}ns)"
            )
        unknown = [op for op in ops if op not in OPS]
        if not fields or not ops or unknown or len(set(ops)) != len(ops) or len(set(fields)) != len(fields):
            raise StageConfigError(
                f"aggregate needs distinct fields and distinct ops from {', '.join(OPS)}; "
                f"got fields={list(fields)} ops={list(ops)}"
            )
        self.name = name
        self.fields = tuple(fields)
        self.ops = tuple(ops)
        self.window_ns = window_ns
        self.hop_ns = hop_ns
        self.allowed_lateness_ns = allowed_lateness_ns
        self.idle_timeout_ns = window_ns + allowed_lateness_ns if idle_timeout_ns is None else idle_timeout_ns
        self.counters = StageCounters()
        self.last_error: str | None = None
        self._paths = [parse_path(f) for f in fields]
        self._getters: list[Getter] = [make_getter(p) for p in self._paths]
        self._columns = [(i, f"{field_name(p)}_{op}", op) for i, p in enumerate(self._paths) for op in ops]
        names = [c[1] for c in self._columns]
        if len(set(names)) != len(names):
            raise StageConfigError(f"aggregate: output field names collide: {names}")
        self._state: dict[tuple[str, str], _KeyState] = {}

    def process(self, sample: Sample, now_ns: int) -> list[Sample]:
        """Add the sample's values to each window it falls in that is still open; returns the windows the
        key's watermark closed (a sample whose windows are all closed counts as late)."""
        counters = self.counters
        counters.received += 1
        try:
            values = [_number(get(sample.value)) for get in self._getters]
        except (LookupError, TypeError, ValueError) as exc:
            counters.errors += 1
            self.last_error = f"{type(exc).__name__}: {exc}"
            return []
        key = (sample.robot, sample.topic)
        state = self._state.get(key)
        if state is None:
            state = self._state[key] = _KeyState()
        state.last_arrival_ns = now_ns
        stamp = sample.stamp_ns
        windows = [
            start
            for start in window_starts(stamp, self.window_ns, self.hop_ns)
            if start + self.window_ns > state.watermark
        ]
        if not windows:
            counters.late += 1
            return []
        counters.passed += 1
        nans = sum(1 for v in values if math.isnan(v))
        counters.nan += nans
        for start in windows:
            window = state.windows.get(start)
            if window is None:
                window = state.windows[start] = Window(start, len(values))
            window.count += 1
            for stats, value in zip(window.stats, values, strict=True):
                if nans == 0 or not math.isnan(value):
                    stats.add(value, stamp)
        if stamp <= state.max_stamp:
            return []
        state.max_stamp = stamp
        watermark = stamp - self.allowed_lateness_ns
        if watermark <= state.watermark:
            return []
        state.watermark = watermark
        return self._emit(key, state, lambda start: start + self.window_ns <= watermark)

    def tick(self, now_ns: int) -> list[Sample]:
        """Close and emit every window of the keys that received nothing for ``idle_timeout_ns``."""
        out: list[Sample] = []
        for key, state in self._state.items():
            if state.windows and now_ns - state.last_arrival_ns >= self.idle_timeout_ns:
                last_end = max(state.windows) + self.window_ns
                state.watermark = max(state.watermark, last_end)
                out.extend(self._emit(key, state, lambda _start: True))
        return out

    def _emit(self, key: tuple[str, str], state: _KeyState, due: Callable[[int], bool]) -> list[Sample]:
        starts = sorted(start for start in state.windows if due(start))
        out = []
        robot, topic = key
        for start in starts:
            window = state.windows.pop(start)
            end = start + self.window_ns
            record: dict[str, Any] = {
                "robot": robot,
                "window_start_ns": start,
                "window_end_ns": end,
                "count": window.count,
            }
            for index, column, op in self._columns:
                record[column] = window.stats[index].result(op)
            out.append(Sample(robot, topic, end, record, None))
        self.counters.emitted += len(out)
        return out

    @property
    def open_windows(self) -> int:
        """Windows open now, over all keys."""
        return sum(len(state.windows) for state in self._state.values())

    def output_schema(self, input_schema: dict[str, Any]) -> dict[str, Any]:
        """The derived record schema of the windows (robot, window bounds, count, one column per field and
        op); raises ``StageConfigError`` when a field is not a number."""
        index, root = root_node(input_schema)
        for text, steps in zip(self.fields, self._paths, strict=True):
            kind = kind_of(resolve_path(index, root, steps))
            if kind != "number":
                raise StageConfigError(
                    f"aggregate: field {text!r} of {index.fullname_of(root)} is {kind}, not a number "
                    "(aggregate numeric scalars; index an array element, e.g. ranges[0])"
                )
        source = index.fullname_of(root) or "record"
        type_name = source.rpartition(".")[2]
        fields: list[dict[str, Any]] = [
            {"name": "robot", "type": "string"},
            {"name": "window_start_ns", "type": "long", "doc": "window start, ns since the epoch, inclusive"},
            {"name": "window_end_ns", "type": "long", "doc": "window end, ns since the epoch, exclusive"},
            {"name": "count", "type": "long", "doc": "samples in the window"},
        ]
        for index_, column, op in self._columns:
            source_field = self.fields[index_]
            doc = f"{'population stddev' if op == 'stddev' else op} of {source_field} (NaN skipped)"
            if op == "count":
                fields.append({"name": column, "type": "long", "doc": f"non-NaN values of {source_field}"})
            else:
                fields.append({"name": column, "type": ["null", "double"], "default": None, "doc": doc})
        return {
            "type": "record",
            "name": f"{type_name}_{short_hash([source, list(self.fields), list(self.ops)])}",
            "namespace": AGG_NAMESPACE,
            "doc": f"Windowed aggregate of {source}",
            "fields": fields,
        }
