"""repeater.telemetry: the repeater's totals -> its own metric families and its health."""

from __future__ import annotations

import pytest

from fleetlink.common.metrics import MetricsRecorder
from fleetlink.repeater.shared import RepeaterStats
from fleetlink.repeater.telemetry import RepeaterTelemetry

pytestmark = pytest.mark.unit


def test_increases_are_reported_once_and_health_follows_the_link() -> None:
    rec = MetricsRecorder()
    telemetry = RepeaterTelemetry(rec)
    stats = RepeaterStats(applied=2, duplicates=1, expired_on_arrival=1, rejected=1, malformed=1)
    stats.by_topic["/tb4_01/cmd_lightring"] += 5
    health = telemetry.observe(stats, link_up=True, active=1, pending=0)
    assert health.state == "ok"
    assert rec.value("fleetlink_commands", command="/tb4_01/cmd_lightring", outcome="published") == 5
    assert rec.value("fleetlink_commands", command="", outcome="applied") == 2
    assert rec.value("fleetlink_commands", command="", outcome="refused") == 2
    assert rec.value("fleetlink_repeater_link_up") == 1
    assert rec.value("fleetlink_repeater_active_commands") == 1
    stats.by_topic["/tb4_01/cmd_lightring"] += 3
    stats.applied += 1
    down = telemetry.observe(stats, link_up=False, active=0, pending=4)
    assert rec.value("fleetlink_commands", command="/tb4_01/cmd_lightring", outcome="published") == 8
    assert rec.value("fleetlink_commands", command="", outcome="applied") == 3
    assert rec.value("fleetlink_commands", command="", outcome="expired") == 1
    assert down.state == "degraded"
    assert [p.reason for p in down.problems] == ["uplink_unreachable"]
    assert "4 status event(s)" in down.problems[0].detail
    assert rec.value("fleetlink_repeater_link_up") == 0
    assert rec.value("fleetlink_health", state="degraded") == 1
