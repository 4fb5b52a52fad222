"""``on_change``: forward a sample only when a chosen field moved, with an optional heartbeat.

Per (robot, topic) the stage remembers the last *forwarded* value of each field. A sample is
forwarded when any field differs from it: numbers by more than ``deadband`` (``|new - old| >
deadband``; NaN counts as different from any number, and equal to NaN), numeric arrays when any
element does or the length changes, records field by field, anything else by inequality. The
first sample of a key is always forwarded.

Heartbeat (processing time): when nothing was forwarded for ``heartbeat_ns`` a sample goes out
anyway: the arriving one in ``process``, or from ``tick`` the newest suppressed sample (held for
that purpose). A robot that falls silent therefore stays silent: heartbeats only ever carry
real, recent samples and prove liveness, never repeat old data.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fleetlink.edge.stages.avro import resolve_path, root_node
from fleetlink.edge.stages.base import Sample, StageCounters
from fleetlink.edge.stages.paths import Getter, Steps, make_getter, parse_path

_SAMPLE_ERRORS = (LookupError, TypeError, ValueError)


def changed(old: Any, new: Any, deadband: float) -> bool:  # noqa: PLR0911 - one branch per kind
    """Whether ``new`` differs from ``old`` by more than ``deadband`` (see the module docstring)."""
    if isinstance(old, np.ndarray) or isinstance(new, np.ndarray):
        left, right = np.asarray(old), np.asarray(new)
        if left.shape != right.shape:
            return True
        if left.dtype.kind in "iufb" and right.dtype.kind in "iufb":
            a64, b64 = left.astype(np.float64), right.astype(np.float64)
            nan_a, nan_b = np.isnan(a64), np.isnan(b64)
            if bool((nan_a != nan_b).any()):
                return True
            with np.errstate(invalid="ignore"):
                diff = np.abs(a64 - b64)
            return bool((diff > deadband).any() | ((a64 != b64) & ~np.isfinite(diff) & ~nan_a).any())
        return bool((left != right).any())
    if isinstance(old, bool) or isinstance(new, bool) or isinstance(old, str | bytes | bytearray):
        return bool(old != new)
    if isinstance(old, int | float | np.number) and isinstance(new, int | float | np.number):
        x, y = float(old), float(new)
        if math.isnan(x) or math.isnan(y):
            return math.isnan(x) != math.isnan(y)
        if math.isinf(x) or math.isinf(y):
            return x != y
        return abs(y - x) > deadband
    if isinstance(old, Mapping) and isinstance(new, Mapping):
        if old.keys() != new.keys():
            return True
        return any(changed(old[k], new[k], deadband) for k in old)
    if isinstance(old, Sequence) and isinstance(new, Sequence):
        if len(old) != len(new):
            return True
        return any(changed(a, b, deadband) for a, b in zip(old, new, strict=True))
    return bool(old != new)


@dataclass(slots=True)
class _KeyState:
    values: tuple[Any, ...]
    forwarded_ns: int
    pending: Sample | None = None
    pending_values: tuple[Any, ...] = ()


class OnChangeStage:
    """Forwards a sample when any of ``fields`` moved (numbers by more than ``deadband``) since the last
    forwarded one of its (robot, topic); with ``heartbeat_ns``, also a held sample after that long."""

    def __init__(
        self,
        fields: Sequence[str],
        deadband: float = 0.0,
        heartbeat_ns: int | None = None,
        *,
        name: str = "on_change",
    ) -> None:
        if not fields:
            raise ValueError("on_change needs at least one field")
        if deadband < 0 or math.isnan(deadband):
            raise ValueError(f"on_change deadband must be >= 0, got {deadband}")
        self.name = name
        self.fields = tuple(fields)
        self.deadband = deadband
        self.heartbeat_ns = heartbeat_ns
        self.counters = StageCounters()
        self.last_error: str | None = None
        self._steps: list[Steps] = [parse_path(f) for f in fields]
        self._getters: list[Getter] = [make_getter(s) for s in self._steps]
        self._state: dict[tuple[str, str], _KeyState] = {}

    def process(self, sample: Sample, now_ns: int) -> list[Sample]:
        """The sample if a field moved since the key's last forwarded sample (or a heartbeat is due), else
        nothing; with a heartbeat the unchanged sample is held, replacing an older held one."""
        counters = self.counters
        counters.received += 1
        try:
            values = tuple(get(sample.value) for get in self._getters)
        except _SAMPLE_ERRORS as exc:
            counters.errors += 1
            self.last_error = f"{type(exc).__name__}: {exc}"
            return []
        key = (sample.robot, sample.topic)
        state = self._state.get(key)
        if state is not None:
            due = self.heartbeat_ns is not None and now_ns - state.forwarded_ns >= self.heartbeat_ns
            try:
                moved = due or any(
                    changed(old, new, self.deadband) for old, new in zip(state.values, values, strict=True)
                )
            except _SAMPLE_ERRORS as exc:  # values that cannot be compared (e.g. ragged arrays)
                counters.errors += 1
                self.last_error = f"{type(exc).__name__}: {exc}"
                return []
            if not moved:
                if self.heartbeat_ns is None:
                    counters.dropped += 1
                    return []
                if state.pending is not None:
                    counters.dropped += 1  # superseded by a newer suppressed sample
                state.pending = sample
                state.pending_values = values
                return []
            if state.pending is not None:
                counters.dropped += 1  # superseded by the sample forwarded now
        self._state[key] = _KeyState(values, now_ns)
        counters.passed += 1
        counters.emitted += 1
        return [sample]

    def tick(self, now_ns: int) -> list[Sample]:
        """The held samples of the keys whose heartbeat is due (nothing without a heartbeat)."""
        if self.heartbeat_ns is None:
            return []
        out: list[Sample] = []
        for state in self._state.values():
            pending = state.pending
            if pending is not None and now_ns - state.forwarded_ns >= self.heartbeat_ns:
                state.values = state.pending_values
                state.forwarded_ns = now_ns
                state.pending = None
                state.pending_values = ()
                out.append(pending)
        self.counters.passed += len(out)
        self.counters.emitted += len(out)
        return out

    @property
    def held(self) -> int:
        """Samples held for a heartbeat now."""
        return sum(1 for state in self._state.values() if state.pending is not None)

    def output_schema(self, input_schema: dict[str, Any]) -> dict[str, Any]:
        """Identity; checks that every field exists in ``input_schema``."""
        index, root = root_node(input_schema)
        for steps in self._steps:
            resolve_path(index, root, steps)
        return input_schema
