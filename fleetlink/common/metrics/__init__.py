"""Metrics and health for every fleetlink process, through one small interface.

Components report through ``Metrics`` (``on_received``, ``on_spooled``, ``on_sent``,
``on_acked``, ``on_dead_letter``, ``on_gap`` ...); ``PrometheusMetrics`` exports them,
``MetricsRecorder`` keeps them for tests. ``serve_metrics`` serves ``/metrics`` and ``/health``.
Every metric is listed in ``families`` and in docs/metrics.md.
"""

from fleetlink.common.metrics.api import HEALTH_STATES, FamilyMetrics, Metrics, NullMetrics
from fleetlink.common.metrics.deltas import CounterDeltas, RecentIncrease
from fleetlink.common.metrics.errors import ServeError
from fleetlink.common.metrics.families import FAMILIES, Family, family
from fleetlink.common.metrics.health import Health, Problem, State
from fleetlink.common.metrics.prometheus import CONTENT_TYPE, PrometheusMetrics
from fleetlink.common.metrics.recorder import MetricsRecorder
from fleetlink.common.metrics.server import (
    HttpServer,
    add_metrics_routes,
    metrics_app,
    serve_metrics,
    split_listen,
)

__all__ = [
    "CONTENT_TYPE",
    "FAMILIES",
    "HEALTH_STATES",
    "CounterDeltas",
    "Family",
    "FamilyMetrics",
    "Health",
    "HttpServer",
    "Metrics",
    "MetricsRecorder",
    "NullMetrics",
    "Problem",
    "PrometheusMetrics",
    "RecentIncrease",
    "ServeError",
    "State",
    "add_metrics_routes",
    "family",
    "metrics_app",
    "serve_metrics",
    "split_listen",
]
