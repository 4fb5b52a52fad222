"""``throttle``: at most ``hz`` samples per second per (robot, topic), on processing time.

Time is cut into periods of ``1/hz`` aligned on the epoch (``now_ns // period_ns``), per key:

* ``keep: first`` forwards the first sample of each period and drops the rest (no delay);
* ``keep: latest`` holds the newest sample of the period and emits it once the period is over:
  from ``process`` of the key's next sample or from ``tick`` (so it adds up to one period, plus
  the tick interval, of delay, and always delivers the freshest value).

Processing time (``now_ns``), not the source stamps, decides: the throttle protects the link,
and it must also hold for robots whose clocks are wrong or that replay old data.
"""

from __future__ import annotations

from typing import Any, Literal

from fleetlink.edge.stages.base import Sample, StageCounters

Keep = Literal["first", "latest"]


class ThrottleStage:
    """At most ``hz`` samples per second per (robot, topic) on processing time, keeping the first or the
    latest sample of each period."""

    def __init__(self, hz: float, keep: Keep = "latest", *, name: str = "throttle") -> None:
        if not hz > 0:
            raise ValueError(f"throttle hz must be > 0, got {hz}")
        self.name = name
        self.hz = hz
        self.keep = keep
        self.period_ns = max(1, round(1e9 / hz))
        self.counters = StageCounters()
        self._last_period: dict[tuple[str, str], int] = {}  # keep: first
        self._held: dict[tuple[str, str], tuple[int, Sample]] = {}  # keep: latest

    def process(self, sample: Sample, now_ns: int) -> list[Sample]:
        """``keep: first``: the sample if it is the first of its period. ``keep: latest``: holds it and
        returns the sample held from an earlier period, if any."""
        counters = self.counters
        counters.received += 1
        key = (sample.robot, sample.topic)
        period = now_ns // self.period_ns
        if self.keep == "first":
            last = self._last_period.get(key)
            if last is not None and last >= period:
                counters.dropped += 1
                return []
            self._last_period[key] = period
            counters.passed += 1
            counters.emitted += 1
            return [sample]
        held = self._held.get(key)
        self._held[key] = (period, sample)
        if held is None:
            return []
        if held[0] >= period:
            counters.dropped += 1
            return []
        counters.passed += 1
        counters.emitted += 1
        return [held[1]]

    def tick(self, now_ns: int) -> list[Sample]:
        """The held samples whose period is over (``keep: latest``)."""
        if not self._held:
            return []
        period = now_ns // self.period_ns
        due = [key for key, (held_period, _) in self._held.items() if held_period < period]
        out = [self._held.pop(key)[1] for key in due]
        self.counters.passed += len(out)
        self.counters.emitted += len(out)
        return out

    @property
    def held(self) -> int:
        """Samples held until their period ends now."""
        return len(self._held)

    def output_schema(self, input_schema: dict[str, Any]) -> dict[str, Any]:
        """The input schema: throttling does not change the records."""
        return input_schema
