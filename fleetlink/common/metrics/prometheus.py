"""``PrometheusMetrics``: ``Metrics`` exported in the Prometheus text format.

Each instance owns its ``CollectorRegistry`` (never the process-global one), so two components
in one process (tests run an edge and an uplink side by side) do not collide.
"""

from __future__ import annotations

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram
from prometheus_client.exposition import CONTENT_TYPE_LATEST, generate_latest

from fleetlink import __version__
from fleetlink.common.metrics.api import FamilyMetrics
from fleetlink.common.metrics.families import LATENCY_BUCKETS, Family, families_of, family

Metric = Counter | Gauge | Histogram

CONTENT_TYPE = CONTENT_TYPE_LATEST


class PrometheusMetrics(FamilyMetrics):
    """The families of ``component`` (``edge``, ``uplink``, ``repeater``) and those of every
    process, registered in a registry of its own: a process exports no family of another, so
    an alert on ``fleetlink_wan_link_up == 0`` fires for edges alone. A report into a family
    the component does not export is dropped."""

    def __init__(self, component: str, *, registry: CollectorRegistry | None = None) -> None:
        self.component = component
        self.registry = registry if registry is not None else CollectorRegistry(auto_describe=True)
        self._metrics: dict[str, Metric] = {}
        for fam in families_of(component):
            self._metrics[fam.name] = _make(fam, self.registry)
        self._set(family("fleetlink_build_info"), (component, __version__), 1)

    def exports(self, name: str) -> bool:
        """Whether this component exports the family ``name`` (``_total`` suffix optional)."""
        return family(name).name in self._metrics

    def _metric(self, fam: Family, labels: tuple[str, ...]) -> Metric | None:
        metric = self._metrics.get(fam.name)
        if metric is None:
            return None
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

    def _observe_buckets(self, fam: Family, counts: tuple[int, ...], total: float) -> None:
        """Add ``counts[i]`` observations to bucket ``i`` (non-cumulative, ``LATENCY_BUCKETS``
        then +Inf) and ``total`` to the sum: observations made elsewhere and counted there."""
        metric = self._metric(fam, ())
        if not isinstance(metric, Histogram):
            return
        buckets = metric._buckets  # prometheus_client has no bulk observe: its own buckets
        for i, n in enumerate(counts[: len(buckets)]):
            if n > 0:
                buckets[i].inc(n)
        if total > 0:
            metric._sum.inc(total)

    def render(self) -> bytes:
        """The registry in the Prometheus text format (``CONTENT_TYPE``)."""
        return generate_latest(self.registry)


def _make(fam: Family, registry: CollectorRegistry) -> Metric:
    if fam.kind == "counter":
        return Counter(fam.name, fam.help, fam.labels, registry=registry)
    if fam.kind == "gauge":
        return Gauge(fam.name, fam.help, fam.labels, registry=registry)
    return Histogram(fam.name, fam.help, fam.labels, registry=registry, buckets=LATENCY_BUCKETS)
