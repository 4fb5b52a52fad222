"""fleetlink.common.metrics: the Metrics interface, its Prometheus and in-memory implementations,
cumulative-to-increment helpers and the health model (no sockets)."""

from __future__ import annotations

import re

import pytest
from fastapi.testclient import TestClient
from prometheus_client.parser import text_string_to_metric_families

from fleetlink.common.metrics import (
    FAMILIES,
    CounterDeltas,
    Health,
    MetricsRecorder,
    NullMetrics,
    Problem,
    PrometheusMetrics,
    RecentIncrease,
    ServeError,
    family,
    metrics_app,
    split_listen,
)
from fleetlink.common.metrics.api import FamilyMetrics, Metrics
from tests.paths import DOCS as DOCS_ROOT

DOCS = DOCS_ROOT / "metrics.md"


def samples(metrics: PrometheusMetrics) -> dict[tuple[str, tuple[tuple[str, str], ...]], float]:
    out = {}
    for fam in text_string_to_metric_families(metrics.render().decode()):
        for s in fam.samples:
            out[(s.name, tuple(sorted(s.labels.items())))] = s.value
    return out


def drive(m: Metrics) -> None:
    """One call of every method (what the tables below expect)."""
    m.on_received("ir", 5)
    m.on_emitted("ir", None, 3)
    m.on_emitted("ir", "throttle", 4)
    m.on_dropped("ir", "throttle", "dropped", 1)
    m.on_dropped("ir", None, "type_mismatch", 2)
    m.on_dead_letter("ir", "decode", 1)
    m.on_dead_letter("ir")
    m.on_gap("/tb4_01/ir", 7)
    m.on_spooled(3, 300, "durable")
    m.on_spool_dropped("durable", "dropped_oldest", 2)
    m.on_sent(1, 3, 200)
    m.on_acked(1, 3, 0.04)
    m.on_acked(1, 1)
    m.on_wan_failure("timeout")
    m.set_spool("durable", nbytes=300, capacity_bytes=1000, depth=3, in_flight=1, oldest_age_s=2.5)
    m.set_wan(in_flight=1, link_up=True)
    m.set_robots(2)
    m.on_ingested("site-a", "ok", 3, 1)
    m.on_delivered("fleet.ir", True, 0.003)
    m.on_delivered("fleet.ir", False, 0.2)
    m.on_command("lightring", "published")
    m.on_ack_latencies((0, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1), 70.004)
    m.on_registry_error("unavailable", 2)
    m.set_command_lag(4.5)
    m.set_repeater(link_up=False, active=3)
    m.set_health("degraded")


EXPECTED = [
    ("fleetlink_mapping_received_total", {"mapping": "ir"}, 5),
    ("fleetlink_mapping_emitted_total", {"mapping": "ir"}, 3),
    ("fleetlink_stage_emitted_total", {"mapping": "ir", "stage": "throttle"}, 4),
    ("fleetlink_stage_dropped_total", {"mapping": "ir", "stage": "throttle", "reason": "dropped"}, 1),
    ("fleetlink_mapping_dropped_total", {"mapping": "ir", "reason": "type_mismatch"}, 2),
    ("fleetlink_mapping_dead_lettered_total", {"mapping": "ir", "stage": "decode"}, 1),
    ("fleetlink_mapping_dead_lettered_total", {"mapping": "ir", "stage": ""}, 1),
    ("fleetlink_sequence_gaps_total", {"topic": "/tb4_01/ir"}, 7),
    ("fleetlink_spool_appended_records_total", {"stream": "durable"}, 3),
    ("fleetlink_spool_appended_bytes_total", {"stream": "durable"}, 300),
    ("fleetlink_spool_dropped_records_total", {"stream": "durable", "reason": "dropped_oldest"}, 2),
    ("fleetlink_wan_sent_batches_total", {}, 1),
    ("fleetlink_wan_sent_records_total", {}, 3),
    ("fleetlink_wan_sent_bytes_total", {}, 200),
    ("fleetlink_wan_acked_batches_total", {}, 2),
    ("fleetlink_wan_acked_records_total", {}, 4),
    ("fleetlink_wan_failures_total", {"reason": "timeout"}, 1),
    ("fleetlink_spool_bytes", {"stream": "durable"}, 300),
    ("fleetlink_spool_capacity_bytes", {"stream": "durable"}, 1000),
    ("fleetlink_spool_depth_records", {"stream": "durable"}, 3),
    ("fleetlink_spool_in_flight_records", {"stream": "durable"}, 1),
    ("fleetlink_spool_oldest_age_seconds", {"stream": "durable"}, 2.5),
    ("fleetlink_wan_in_flight_batches", {}, 1),
    ("fleetlink_wan_link_up", {}, 1),
    ("fleetlink_robots_registered", {}, 2),
    ("fleetlink_ingest_batches_total", {"site": "site-a", "status": "ok"}, 1),
    ("fleetlink_ingest_records_total", {"site": "site-a"}, 3),
    ("fleetlink_ingest_dead_lettered_total", {"site": "site-a"}, 1),
    ("fleetlink_kafka_delivered_total", {"topic": "fleet.ir", "result": "ok"}, 1),
    ("fleetlink_kafka_delivered_total", {"topic": "fleet.ir", "result": "error"}, 1),
    ("fleetlink_commands_total", {"command": "lightring", "outcome": "published"}, 1),
    ("fleetlink_health", {"state": "degraded"}, 1),
    ("fleetlink_health", {"state": "ok"}, 0),
    ("fleetlink_wan_ack_latency_seconds_count", {}, 4),
    ("fleetlink_kafka_delivery_latency_seconds_count", {}, 2),
    ("fleetlink_registry_errors_total", {"reason": "unavailable"}, 2),
    ("fleetlink_command_lag_seconds", {}, 4.5),
    ("fleetlink_repeater_link_up", {}, 0),
    ("fleetlink_repeater_active_commands", {}, 3),
]


def component_of(name: str) -> str:
    """The process that exports ``name`` (a sample name: ``_total``, ``_count`` ...)."""
    base = re.sub(r"_(total|count|sum|bucket)$", "", name)
    owner = family(base).component
    return "edge" if owner == "any" else owner


@pytest.mark.parametrize(("name", "labels", "value"), EXPECTED)
def test_prometheus_exposes_each_call(name: str, labels: dict[str, str], value: float) -> None:
    metrics = PrometheusMetrics(component_of(name))
    drive(metrics)
    assert samples(metrics)[(name, tuple(sorted(labels.items())))] == value


@pytest.mark.parametrize("component", ["edge", "uplink", "repeater"])
def test_each_process_exports_its_own_families_only(component: str) -> None:
    metrics = PrometheusMetrics(component)
    drive(metrics)  # every method, those of the other processes included: they are dropped
    exported = {re.sub(r"_(total|count|sum|bucket|created)$", "", name) for name, _ in samples(metrics)}
    own = {f.name for f in FAMILIES if f.component in (component, "any")}
    assert exported <= own
    assert "fleetlink_build_info" in exported
    others = {f.name for f in FAMILIES if f.component not in (component, "any")}
    assert not exported & others
    if component != "edge":
        assert "fleetlink_wan_link_up" not in exported  # an alert on it fires for edges alone


def test_ack_latencies_counted_elsewhere_fill_the_histogram() -> None:
    metrics = PrometheusMetrics("edge")
    metrics.on_ack_latencies((0, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1), 70.004)
    found = samples(metrics)
    assert found[("fleetlink_wan_ack_latency_seconds_count", ())] == 3
    assert found[("fleetlink_wan_ack_latency_seconds_sum", ())] == pytest.approx(70.004)
    assert found[("fleetlink_wan_ack_latency_seconds_bucket", (("le", "0.001"),))] == 0
    assert found[("fleetlink_wan_ack_latency_seconds_bucket", (("le", "0.0025"),))] == 2
    assert found[("fleetlink_wan_ack_latency_seconds_bucket", (("le", "60.0"),))] == 2
    assert found[("fleetlink_wan_ack_latency_seconds_bucket", (("le", "+Inf"),))] == 3


@pytest.mark.parametrize(("name", "labels", "value"), [e for e in EXPECTED if not e[0].endswith("_count")])
def test_recorder_keeps_the_same_values(name: str, labels: dict[str, str], value: float) -> None:
    rec = MetricsRecorder()
    drive(rec)
    assert rec.value(name, **labels) == value


def test_recorder_observations_and_totals() -> None:
    rec = MetricsRecorder()
    drive(rec)
    assert rec.observations("fleetlink_wan_ack_latency_seconds") == [0.04]
    assert rec.bucket_counts("fleetlink_wan_ack_latency_seconds")[1] == 2
    assert rec.observations("fleetlink_kafka_delivery_latency_seconds") == [0.003, 0.2]
    assert rec.total("fleetlink_mapping_dead_lettered", mapping="ir") == 2
    assert rec.total("fleetlink_kafka_delivered") == 2
    with pytest.raises(KeyError):
        rec.value("fleetlink_mapping_received")  # the mapping label is missing
    with pytest.raises(KeyError):
        family("fleetlink_no_such_metric")


def test_zero_and_negative_counts_are_not_reported() -> None:
    rec = MetricsRecorder()
    rec.on_received("ir", 0)
    rec.on_received("ir", -3)
    assert rec.series() == {}


def test_each_process_has_its_own_registry() -> None:
    edge, uplink = PrometheusMetrics("edge"), PrometheusMetrics("uplink")
    edge.on_received("ir", 2)
    assert samples(edge)[("fleetlink_mapping_received_total", (("mapping", "ir"),))] == 2
    assert ("fleetlink_mapping_received_total", (("mapping", "ir"),)) not in samples(uplink)
    build = [k for k in samples(uplink) if k[0] == "fleetlink_build_info"]
    assert build == [("fleetlink_build_info", (("component", "uplink"), ("version", "0.1.0")))]


def test_null_metrics_accepts_everything() -> None:
    drive(NullMetrics())


def test_every_family_is_documented() -> None:
    text = DOCS.read_text(encoding="utf-8")
    documented = set(re.findall(r"`(fleetlink_[a-z_]+)`", text))
    assert {f.exposed for f in FAMILIES} <= documented
    for fam in FAMILIES:
        for label in fam.labels:
            assert re.search(rf"`{fam.exposed}`[^\n]*`{label}`", text), (fam.exposed, label)


def test_every_protocol_method_is_implemented_once() -> None:
    names = {n for n in vars(Metrics) if n.startswith(("on_", "set_"))}
    assert names == {n for n in vars(FamilyMetrics) if n.startswith(("on_", "set_"))}


# -- deltas ---------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("totals", "deltas"),
    [
        ([0, 5, 5, 9], [0, 5, 0, 4]),
        ([3, 10, 2, 4], [3, 7, 2, 2]),  # 10 -> 2: the owner was rebuilt, its new total counts
        ([7], [7]),
    ],
)
def test_counter_deltas(totals: list[int], deltas: list[int]) -> None:
    d = CounterDeltas()
    assert [d.delta("k", t) for t in totals] == deltas


def test_counter_deltas_forget() -> None:
    d = CounterDeltas()
    d.delta("a", 5)
    d.delta("b", 5)
    d.forget({"a"})
    assert (d.delta("a", 6), d.delta("b", 6)) == (1, 6)


@pytest.mark.parametrize(
    ("looks", "expected"),
    [
        # (time, running total) -> increase over the last 60 s, measured from the newest look >= 60 s old
        ([(10, 0), (20, 3)], [0, 3]),
        ([(10, 2), (65, 2), (75, 2)], [2, 2, 0]),  # at 65 s the baseline is still (0 s, 0)
        ([(30, 5), (100, 5)], [5, 0]),
        ([(30, 5), (50, 8), (95, 9), (130, 9)], [5, 8, 4, 1]),
        ([(10, 5), (20, 1)], [5, 1]),  # reset: the new total is the increase
    ],
)
def test_recent_increase(looks: list[tuple[float, int]], expected: list[int]) -> None:
    tracker = RecentIncrease(60, created_s=0)
    assert [tracker.update(t, v) for t, v in looks] == expected


def test_recent_increase_rejects_empty_window() -> None:
    with pytest.raises(ValueError, match="window"):
        RecentIncrease(0, created_s=0)


# -- health ---------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("severities", "state", "status"),
    [
        ([], "ok", 200),
        (["degraded"], "degraded", 200),
        (["degraded", "failed", "degraded"], "failed", 503),
    ],
)
def test_health_state_is_the_worst_problem(severities: list[str], state: str, status: int) -> None:
    problems = [
        Problem("mapping", f"m{i}", "dead_letters", "x", severity=s)  # type: ignore[arg-type]
        for i, s in enumerate(severities)
    ]
    health = Health.of(problems, robots=3)
    assert (health.state, health.http_status) == (state, status)
    body = health.as_dict()
    assert body["state"] == state
    assert body["robots"] == 3
    assert body["degraded_mappings"] == {f"m{i}": ["dead_letters"] for i in range(len(severities))}


# -- the small app ----------------------------------------------------------------------------
def test_metrics_app_serves_metrics_and_health() -> None:
    metrics = PrometheusMetrics("uplink")
    failed = Health.of([Problem("kafka", "producer", "fatal", "fenced", severity="failed")])
    refreshed: list[int] = []
    client = TestClient(metrics_app(metrics, lambda: failed, refresh=lambda: refreshed.append(1)))
    metrics.on_ingested("a", "ok", 4)
    scrape = client.get("/metrics")
    assert scrape.status_code == 200
    assert scrape.headers["content-type"].startswith("text/plain")
    assert samples(metrics)[("fleetlink_ingest_records_total", (("site", "a"),))] == 4
    health = client.get("/health")
    assert health.status_code == 503
    assert health.json()["problems"][0]["reason"] == "fatal"
    assert samples(metrics)[("fleetlink_health", (("state", "failed"),))] == 1
    assert len(refreshed) == 2


@pytest.mark.parametrize(
    ("listen", "expected"),
    [
        ("127.0.0.1:8480", ("127.0.0.1", 8480)),
        ("[::1]:0", ("::1", 0)),
        ("localhost:9", ("localhost", 9)),
    ],
)
def test_split_listen(listen: str, expected: tuple[str, int]) -> None:
    assert split_listen(listen) == expected


@pytest.mark.parametrize("listen", ["8480", ":8480", "host:", "host:http", "host:70000"])
def test_split_listen_refuses(listen: str) -> None:
    with pytest.raises(ServeError, match="host:port"):
        split_listen(listen)
