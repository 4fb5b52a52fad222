"""Spool damage through the admin API: listed, degrading health, acknowledged by an operator."""

from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient

from fleetlink.common.metrics import PrometheusMetrics
from fleetlink.edge.admin.backend import BufferState, EdgeSnapshot
from fleetlink.edge.admin.http import create_app
from fleetlink.edge.admin.service import AdminService
from fleetlink.edge.admin.table_backend import TableBackend
from fleetlink.edge.admin.telemetry import EdgeTelemetry
from fleetlink.edge.spool import Spool, SpoolOptions
from tests.unit.edge.admin.world import base_config, fleet_graph

OPTIONS = SpoolOptions(segment_bytes=8192, max_bytes=1 << 20, group_records=1)


def damaged_spool(directory: Path) -> Spool:
    with Spool(directory, OPTIONS) as spool:
        for _ in range(200):  # one append at a time: they fill several segments
            spool.append(b"x" * 100)
    sorted(directory.glob("*.seg"))[1].unlink()
    return Spool(directory, OPTIONS).open()


def test_damage_is_listed_degrades_health_and_is_acknowledged(tmp_path: Path) -> None:
    spool = damaged_spool(tmp_path)
    config = base_config()

    def snapshot() -> EdgeSnapshot:
        unacked = [f.as_dict() for f in spool.damage() if f.acknowledged_ms is None]
        return EdgeSnapshot(
            buffers=(BufferState(spool.stats(), capacity_bytes=OPTIONS.max_bytes),),
            spool_damage={"durable": unacked},
        )

    backend = TableBackend(
        config.mapping_table(),
        fleet_graph(),
        snapshot=snapshot,
        spool_damage=lambda: [f.as_dict() for f in spool.damage()],
        acknowledge_spool_damage=lambda: [f.as_dict() for f in spool.acknowledge_damage()],
    )
    metrics = PrometheusMetrics("edge")
    service = AdminService(config, backend, telemetry=EdgeTelemetry(metrics))
    api = TestClient(create_app(service, metrics=metrics))
    health = api.get("/health").json()
    assert health["state"] == "degraded"
    ((problem),) = health["problems"]
    assert (problem["component"], problem["reason"]) == ("spool", "spool_damage")
    assert "(59 record(s) lost); first: segment_missing in 00000000000000000060.seg" in problem["detail"]
    (listed,) = api.get("/spool/damage").json()
    assert (listed["reason"], listed["first_seq"], listed["last_seq"], listed["records"]) == (
        "segment_missing",
        60,
        118,
        59,
    )
    assert listed["acknowledged_ms"] is None
    answer = api.post("/spool/damage/acknowledge")
    assert answer.status_code == 200
    assert [f["file"] for f in answer.json()["acknowledged"]] == ["00000000000000000060.seg"]
    assert api.get("/health").json()["state"] == "ok"
    assert api.get("/spool/damage").json()[0]["acknowledged_ms"] is not None
    assert api.post("/spool/damage/acknowledge").json() == {"acknowledged": []}
    scraped = api.get("/metrics").text
    assert 'fleetlink_spool_damage_unacknowledged{stream="durable"} 0.0' in scraped
    assert 'fleetlink_spool_dropped_records_total{reason="missing",stream="durable"} 59.0' in scraped
    spool.close()
