"""``MetricsRecorder``: ``Metrics`` kept in memory, for tests (no Prometheus, no sockets)."""

from __future__ import annotations

import threading
from collections import defaultdict

from fleetlink.common.metrics.api import FamilyMetrics
from fleetlink.common.metrics.families import Family, family


class MetricsRecorder(FamilyMetrics):
    """Counter totals, last gauge values and every histogram observation, by family and labels.

    ``rec.value("fleetlink_mapping_received", mapping="ir")`` (the ``_total`` suffix is optional);
    ``rec.observations("fleetlink_wan_ack_latency_seconds")``.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._values: dict[tuple[str, tuple[str, ...]], float] = defaultdict(float)
        self._observed: dict[str, list[float]] = defaultdict(list)
        self._buckets: dict[str, list[int]] = {}

    def _inc(self, fam: Family, labels: tuple[str, ...], n: float) -> None:
        _check(fam, labels)
        with self._lock:
            self._values[(fam.name, labels)] += n

    def _set(self, fam: Family, labels: tuple[str, ...], value: float) -> None:
        _check(fam, labels)
        with self._lock:
            self._values[(fam.name, labels)] = float(value)

    def _observe(self, fam: Family, labels: tuple[str, ...], value: float) -> None:
        _check(fam, labels)
        with self._lock:
            self._observed[fam.name].append(value)

    def _observe_buckets(self, fam: Family, counts: tuple[int, ...], total: float) -> None:
        with self._lock:
            held = self._buckets.setdefault(fam.name, [0] * len(counts))
            for i, n in enumerate(counts):
                held[i] += n
            self._values[(fam.name + "_sum", ())] += total

    def bucket_counts(self, name: str) -> list[int]:
        """Observations added per bucket (``on_ack_latencies``), non-cumulative."""
        with self._lock:
            return list(self._buckets.get(family(name).name, ()))

    def value(self, name: str, **labels: str) -> float:
        """A counter's total or a gauge's value (0 when never reported)."""
        fam = family(name)
        key = tuple(labels[label] for label in fam.labels) if set(labels) == set(fam.labels) else None
        if key is None:
            raise KeyError(f"{fam.name} has labels {fam.labels}, got {sorted(labels)}")
        with self._lock:
            return self._values.get((fam.name, key), 0.0)

    def total(self, name: str, **labels: str) -> float:
        """The sum over every series of ``name`` whose labels include ``labels``."""
        fam = family(name)
        positions = {fam.labels.index(k): v for k, v in labels.items()}
        with self._lock:
            return sum(
                v
                for (n, key), v in self._values.items()
                if n == fam.name and all(key[i] == want for i, want in positions.items())
            )

    def observations(self, name: str) -> list[float]:
        """Every value observed so far in histogram ``name``, in order, over all labels."""
        with self._lock:
            return list(self._observed.get(family(name).name, ()))

    def series(self) -> dict[tuple[str, tuple[str, ...]], float]:
        """A copy of every counter and gauge value, keyed by family name and label values."""
        with self._lock:
            return dict(self._values)


def _check(fam: Family, labels: tuple[str, ...]) -> None:
    if len(labels) != len(fam.labels):
        raise ValueError(f"{fam.name} takes labels {fam.labels}, got {labels}")
