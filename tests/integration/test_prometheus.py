"""The shipped Prometheus files work with the real tools: ``promtool`` checks and tests every
alert rule, and a real Prometheus (Debian's ``prometheus`` package) scraping a running edge,
uplink and repeater sees each process's own families, live rates, a filled ack-latency
histogram and the repeater's command counters, through its HTTP API."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml

from fleetlink.common.metrics.families import LATENCY_BUCKETS
from fleetlink.common.metrics_config import MetricsSection
from fleetlink.edge.admin import EdgeAdmin
from fleetlink.edge.agent import EdgeAgent
from fleetlink.repeater.service import Repeater
from tests.helpers import free_port, wait_until
from tests.integration.test_admin_api import edge_config
from tests.integration.test_commands_harness import (
    RED,
    fleet,
    lightring_bed,
    repeater_config,
    running_uplink,
    wait_repeater_sees,
)
from tests.paths import ROOT

pytestmark = pytest.mark.integration

PROMETHEUS_DIR = ROOT / "deploy" / "prometheus"
DASHBOARD = ROOT / "deploy" / "grafana" / "fleetlink.json"


def tool(name: str) -> str:
    found = shutil.which(name)
    if found is None:
        raise AssertionError(f"{name} is missing: apt-get install -y prometheus (see .ci/run)")
    return found


def run(*argv: str) -> str:
    done = subprocess.run(argv, capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, f"{' '.join(argv)}:\n{done.stdout}\n{done.stderr}"
    return done.stdout


def test_promtool_checks_the_config_and_tests_every_alert() -> None:
    promtool = tool("promtool")
    run(promtool, "check", "config", str(PROMETHEUS_DIR / "prometheus.yml"))
    run(promtool, "check", "rules", str(PROMETHEUS_DIR / "alerts.yml"))
    out = run(promtool, "test", "rules", str(PROMETHEUS_DIR / "alerts_test.yml"))
    assert "SUCCESS" in out
    rules = yaml.safe_load((PROMETHEUS_DIR / "alerts.yml").read_text())
    alerts = {r["alert"] for g in rules["groups"] for r in g["rules"]}
    tests = yaml.safe_load((PROMETHEUS_DIR / "alerts_test.yml").read_text())
    fired = {case["alertname"] for t in tests["tests"] for case in t["alert_rule_test"] if case["exp_alerts"]}
    quiet = {
        case["alertname"] for t in tests["tests"] for case in t["alert_rule_test"] if not case["exp_alerts"]
    }
    assert alerts == fired, f"alerts without a firing test: {sorted(alerts - fired)}"
    assert alerts - {"FleetlinkSpoolFull", "FleetlinkUplinkDeadLetters", "FleetlinkProcessFailed"} <= quiet


class Prometheus:
    def __init__(self, url: str) -> None:
        self.url = url
        self.http = httpx.Client(base_url=url, timeout=10)

    def query(self, expr: str) -> list[dict[str, Any]]:
        answer = self.http.get("/api/v1/query", params={"query": expr}).json()
        assert answer["status"] == "success", (expr, answer)
        result: list[dict[str, Any]] = answer["data"]["result"]
        return result

    def value(self, expr: str) -> float:
        result = self.query(expr)
        return float(result[0]["value"][1]) if result else 0.0

    def jobs_with(self, metric: str) -> set[str]:
        return {r["metric"]["job"] for r in self.query(f"count by (job) ({metric})")}


@contextmanager
def prometheus(tmp: Path, targets: dict[str, str]) -> Iterator[Prometheus]:
    """A real Prometheus scraping ``targets`` (job -> host:port) every second."""
    port = free_port()
    config = {
        "global": {"scrape_interval": "1s", "evaluation_interval": "1s"},
        "rule_files": [str(PROMETHEUS_DIR / "alerts.yml")],
        "scrape_configs": [
            {"job_name": job, "static_configs": [{"targets": [target]}]} for job, target in targets.items()
        ],
    }
    path = tmp / "prometheus.yml"
    path.write_text(json.dumps(config))
    log = (tmp / "prometheus.log").open("w")
    proc = subprocess.Popen(
        [
            tool("prometheus"),
            f"--config.file={path}",
            f"--storage.tsdb.path={tmp / 'data'}",
            f"--web.listen-address=127.0.0.1:{port}",
        ],
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    try:
        server = Prometheus(f"http://127.0.0.1:{port}")

        def ready() -> bool:
            try:
                return server.http.get("/-/ready").status_code == 200
            except httpx.HTTPError:
                return False

        wait_until(ready, 30, interval=0.2, message="prometheus ready")
        yield server
    finally:
        proc.terminate()
        proc.wait(10)
        log.close()


def host_port(url: str) -> str:
    return url.removeprefix("http://").rstrip("/")


def test_prometheus_scrapes_edge_uplink_and_repeater(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    with lightring_bed(kafka_bootstrap, schema_registry_url, period="500ms", lease="20s") as bed:
        metrics = MetricsSection(listen="127.0.0.1:0")
        uplink_config = bed.config.model_copy(update={"metrics": metrics})
        rep_config = repeater_config(bed.site, tmp_path / "state").model_copy(update={"metrics": metrics})
        edge = edge_config(
            tmp_path / "spool",
            bed.site.endpoint,
            site=bed.site.name,
            domain=0,
            topics={
                "registrations": uplink_config.topics.registrations,
                "dead_letter": uplink_config.topics.dead_letter,
            },
        )
        admin = EdgeAdmin(edge, token=None, listen="127.0.0.1:0")
        with (
            running_uplink(uplink_config) as uplink,
            Repeater(rep_config) as repeater,
            fleet(bed.site, bed.ts, bed.leds, robots=2),
            EdgeAgent(admin.load(), stop_timeout_s=0.5) as agent,
        ):
            admin.attach(agent)
            try:
                assert uplink.metrics_url is not None
                assert repeater.metrics_url is not None
                wait_until(lambda: sorted(agent.robots()) == ["tb4_01", "tb4_02"], 15, message="registered")
                wait_repeater_sees(repeater, "/tb4_01/cmd_lightring")
                targets = {
                    "fleetlink-edge": host_port(admin.url),
                    "fleetlink-uplink": host_port(uplink.metrics_url),
                    "fleetlink-repeater": host_port(repeater.metrics_url),
                }
                with prometheus(tmp_path, targets) as prom:
                    wait_until(
                        lambda: prom.value('count(up{job=~"fleetlink-.*"} == 1)') == 3,
                        20,
                        interval=0.5,
                        message="all three targets up",
                    )
                    wait_until(
                        lambda: uplink.directory.site_of("tb4_01") == bed.site.name,
                        15,
                        message="the uplink knows tb4_01's site",
                    )
                    bed.producer.send(bed.topic, "tb4_01", RED, command_id=f"prom-{bed.run}")
                    wait_until(lambda: bed.leds.count("tb4_01", "red") >= 1, 10, message="command applied")
                    checks = {
                        "edge mapping rate": "sum(rate(fleetlink_mapping_received_total[5s]))",
                        "uplink Kafka rate": 'sum(rate(fleetlink_kafka_delivered_total{result="ok"}[5s]))',
                        "edge ack latency": "sum(fleetlink_wan_ack_latency_seconds_count)",
                        "repeater applied": 'sum(fleetlink_commands_total{outcome="applied"})',
                        "repeater published": 'sum(fleetlink_commands_total{outcome="published"})',
                    }
                    wait_until(
                        lambda: all(prom.value(expr) > 0 for expr in checks.values()),
                        30,
                        interval=0.5,
                        message=f"non-zero {list(checks)}",
                    )
                    assert prom.jobs_with("fleetlink_wan_link_up") == {"fleetlink-edge"}
                    assert prom.jobs_with("fleetlink_ingest_batches_total") == {"fleetlink-uplink"}
                    assert prom.jobs_with("fleetlink_repeater_link_up") == {"fleetlink-repeater"}
                    assert prom.jobs_with("fleetlink_build_info") == set(targets)
                    assert prom.value('fleetlink_repeater_link_up{job="fleetlink-repeater"}') == 1
                    assert prom.value("fleetlink_wan_link_up") == 1
                    # the quantile of the histogram the edge fills from its senders' counts, over all
                    # of it: a rate over a window needs two scrapes in it, which a loaded machine's
                    # 1 s scrape timeout may not give
                    buckets = "fleetlink_wan_ack_latency_seconds_bucket"
                    p95 = prom.value(f"histogram_quantile(0.95, sum by (le) ({buckets}))")
                    # in seconds, not ms: no acknowledgement comes later than the ack timeout, so the
                    # quantile lies at most in the bucket that holds the timeout; the estimate is
                    # interpolated within that bucket, and may pass the timeout up to its edge
                    timeout_s = edge.wan.ack_timeout / 1e9
                    assert 0 < p95 <= min(b for b in LATENCY_BUCKETS if b >= timeout_s)
                    for expr in dashboard_queries():
                        prom.query(expr)  # every panel's query is valid PromQL against real data
                    firing = prom.query('ALERTS{alertstate="firing"}')
                    assert firing == [], firing
            finally:
                admin.stop()


def dashboard_queries() -> list[str]:
    data = json.loads(DASHBOARD.read_text())
    exprs = [t["expr"] for p in data["panels"] for t in p.get("targets", ())]
    return [re.sub(r"\$__rate_interval", "10s", e) for e in exprs]
