"""``serve_metrics``: what the uplink and the repeater start (a real socket on loopback)."""

from __future__ import annotations

import httpx
import pytest
from prometheus_client.parser import text_string_to_metric_families

from fleetlink.common.metrics import Health, Problem, PrometheusMetrics, ServeError, serve_metrics


def test_serve_metrics_and_health_on_a_free_port() -> None:
    metrics = PrometheusMetrics("uplink")
    state = {"health": Health.of(())}
    server = serve_metrics("127.0.0.1", 0, metrics, lambda: state["health"])
    port = server.port
    try:
        assert port > 0
        metrics.on_delivered("fleet.imu", ok=True, latency_s=0.004)
        metrics.on_ingested("site-a", "ok", 10)
        text = httpx.get(f"{server.url}/metrics", timeout=5).text
        values = {
            (s.name, tuple(sorted(s.labels.items()))): s.value
            for fam in text_string_to_metric_families(text)
            for s in fam.samples
        }
        assert values[("fleetlink_kafka_delivered_total", (("result", "ok"), ("topic", "fleet.imu")))] == 1
        assert values[("fleetlink_ingest_records_total", (("site", "site-a"),))] == 10
        assert values[("fleetlink_kafka_delivery_latency_seconds_bucket", (("le", "0.005"),))] == 1
        assert httpx.get(f"{server.url}/health", timeout=5).json()["state"] == "ok"
        state["health"] = Health.of([Problem("kafka", "producer", "fatal", "fenced", severity="failed")])
        assert httpx.get(f"{server.url}/health", timeout=5).status_code == 503
        with pytest.raises(ServeError, match="cannot listen"):
            serve_metrics("127.0.0.1", port, PrometheusMetrics("repeater"))
    finally:
        server.stop()
    with pytest.raises(httpx.TransportError):
        httpx.get(f"http://127.0.0.1:{port}/metrics", timeout=2)
