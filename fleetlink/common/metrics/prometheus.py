"""``PrometheusMetrics``: ``Metrics`` exported in the Prometheus text format.

Each instance owns its ``CollectorRegistry`` (never the process-global one), so two components
in one process (tests run an edge and an uplink side by side) do not collide.
"""

from __future__ import annotations

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram
from prometheus_client.exposition import CONTENT_TYPE_LATEST, generate_latest

from fleetlink import __version__
from fleetlink.common.metrics.api import FamilyMetrics
from fleetlink.common.metrics.families import FAMILIES, LATENCY_BUCKETS, Family

Metric = Counter | Gauge | Histogram

CONTENT_TYPE = CONTENT_TYPE_LATEST


class PrometheusMetrics(FamilyMetrics):
    """Every family of ``fleetlink.common.metrics.families`` registered in a registry of its own."""

    def __init__(self, component: str, *, registry: CollectorRegistry | None = None) -> None:
        self.component = component
        self.registry = registry if registry is not None else CollectorRegistry(auto_describe=True)
        self._metrics: dict[str, Metric] = {}
        for fam in FAMILIES:
            self._metrics[fam.name] = _make(fam, self.registry)
        self._set(next(f for f in FAMILIES if f.name == "fleetlink_build_info"), (component, __version__), 1)

    def _metric(self, fam: Family, labels: tuple[str, ...]) -> Metric:
        metric = self._metrics[fam.name]
        return metric.labels(*labels) if labels else metric

    def _inc(self, fam: Family, labels: tuple[str, ...], n: float) -> None:
        metric = self._metric(fam, labels)
        if isinstance(metric, Counter | Gauge):
            metric.inc(n)

    def _set(self, fam: Family, labels: tuple[str, ...], value: float) -> None:
        metric = self._metric(fam, labels)
        if isinstance(metric, Gauge):
            metric.set(value)

    def _observe(self, fam: Family, labels: tuple[str, ...], value: float) -> None:
        metric = self._metric(fam, labels)
        if isinstance(metric, Histogram):
            metric.observe(value)

    def render(self) -> bytes:
        """The registry in the Prometheus text format (``CONTENT_TYPE``)."""
        return generate_latest(self.registry)


def _make(fam: Family, registry: CollectorRegistry) -> Metric:
    if fam.kind == "counter":
        return Counter(fam.name, fam.help, fam.labels, registry=registry)
    if fam.kind == "gauge":
        return Gauge(fam.name, fam.help, fam.labels, registry=registry)
    return Histogram(fam.name, fam.help, fam.labels, registry=registry, buckets=LATENCY_BUCKETS)
