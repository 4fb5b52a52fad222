"""AgentBackend's reading of ``EdgeAgent.snapshot()``, TableBackend, and stage state kept across changes."""

from __future__ import annotations

import dataclasses
from typing import Any

from fleetlink.edge.admin.agent_backend import robots_from_agent, snapshot_from_agent
from fleetlink.edge.admin.backend import MappingCounts, MappingIssue, RobotStatus, WanTotals
from fleetlink.edge.admin.changes import change_mapping
from fleetlink.edge.admin.overlay import Overlay, config_data
from fleetlink.edge.admin.specs import declarations
from fleetlink.edge.admin.table_backend import TableBackend
from fleetlink.edge.spool import SpoolStats
from tests.unit.edge.admin.world import base_config, fleet_graph

SPOOL = SpoolStats(
    stream="durable",
    appended=12,
    acked=9,
    dropped_oldest=0,
    dropped_newest=0,
    corrupt_skipped=1,
    block_timeouts=0,
    disk_full=0,
    stale_acks=0,
    fsyncs=4,
    bytes=300,
    depth=3,
    in_flight=1,
    oldest_append_ms=5,
    segments=1,
    next_seq=13,
)
SENDER = {
    "batches_sent": 3,
    "batches_acked": 2,
    "batches_retried": 1,
    "records_sent": 12,
    "records_acked": 9,
    "records_dead_lettered": 0,
    "bytes_sent": 900,
    "stale_acks": 0,
    "missing_schemas": 0,
    "outages": 1,
    "in_flight": 1,
    "healthy": False,
    "outage_s": 2.5,
    "last_error": "timeout",
}
AGENT: dict[str, Any] = {
    "site": "warehouse-a",
    "edge_id": "edge-1",
    "running": True,
    "robots": {"tb4_01": "tb4"},
    "mappings": {"ir": {"received": 10, "emitted": 4, "dropped": 6, "dead_lettered": 0, "type_mismatch": 1}},
    "stages": {
        "ir": {
            "throttle": {
                "received": 9,
                "passed": 4,
                "dropped": 5,
                "late": 0,
                "errors": 0,
                "emitted": 4,
                "nan": 0,
            }
        }
    },
    "streams": {
        "durable": {"buffer": dataclasses.asdict(SPOOL), "sender": SENDER},
        "memory": {"buffer": {**dataclasses.asdict(SPOOL), "stream": "memory"}},
    },
    "subscriptions": {
        "/tb4_01/ir_intensity": {"type": "x", "received": 10, "gaps": 1, "missing": 3, "unmapped": 2}
    },
}


def test_snapshot_from_agent() -> None:
    config = base_config()
    snap = snapshot_from_agent(AGENT, config)
    assert snap.mappings == {
        "ir": MappingCounts(
            received=10,
            emitted=4,
            dropped=6,
            type_mismatch=1,
            stages={
                "throttle": {
                    "received": 9,
                    "passed": 4,
                    "dropped": 5,
                    "late": 0,
                    "errors": 0,
                    "emitted": 4,
                    "nan": 0,
                }
            },
        )
    }
    assert [(b.stats, b.capacity_bytes) for b in snap.buffers] == [
        (SPOOL, int(config.spool.max_bytes)),
        (dataclasses.replace(SPOOL, stream="memory"), int(config.memory.max_bytes)),
    ]
    assert snap.wan == {
        "durable": WanTotals(
            batches_sent=3,
            records_sent=12,
            bytes_sent=900,
            batches_acked=2,
            records_acked=9,
            batches_retried=1,
            in_flight=1,
        )
    }
    assert snap.wan_link_up is False
    assert snap.sequence_gaps == {"/tb4_01/ir_intensity": 3}
    assert snap.unmapped == {"/tb4_01/ir_intensity": 2}
    assert snap.failure is None


def test_snapshot_from_a_stopped_or_odd_agent() -> None:
    snap = snapshot_from_agent(
        {"running": False, "mappings": {"x": "garbage"}, "streams": {"s": {"buffer": {"a": 1}}}},
        base_config(),
    )
    assert snap.failure == "the edge agent is not running"
    assert snap.mappings == {"x": MappingCounts()}
    assert snap.buffers == ()
    assert snap.wan_link_up is None


def test_unchanged_mappings_keep_their_stage_tuple() -> None:
    config = base_config()
    table = config.mapping_table()
    before = {info.name: info.stages for info in table.list()}
    base = config_data(config)
    proposal = change_mapping(
        base,
        Overlay(),
        "ir",
        {
            "name": "ir",
            "robot_type": "tb4",
            "from": "/{robot}/ir_intensity",
            "to": "fleet.ir",
            "stages": [{"type": "throttle", "hz": 2}],
        },
    )
    robot_types, mappings = declarations(proposal.config, table)
    table.reload(robot_types, mappings)
    after = {info.name: info.stages for info in table.list()}
    assert after["odom_1s"] is before["odom_1s"]  # untouched: the runtime keeps its aggregate windows
    assert after["ir"] is not before["ir"]
    assert after["ir"][0].hz == 2
    fresh_types, _ = declarations(proposal.config)
    assert fresh_types[0].mappings[1].stages is not before["odom_1s"]


def test_table_backend_registers_robots_a_new_type_matches() -> None:
    config = base_config()
    table = config.mapping_table()
    installed: list[str] = []
    backend = TableBackend(
        table, fleet_graph(), register_robots=True, on_install=lambda c: installed.append(c.site)
    )
    data = config_data(config)
    data["robot_types"]["kobuki"] = {"match": "/kb_*", "mappings": []}
    changed = type(config).model_validate(data)
    backend.install(changed, *declarations(changed, table))
    assert table.robots() == {"kb_01": "kobuki", "tb4_01": "tb4", "tb4_02": "tb4"}
    assert [(r.robot, r.robot_type) for r in backend.robots()] == [
        ("kb_01", "kobuki"),
        ("tb4_01", "tb4"),
        ("tb4_02", "tb4"),
    ]
    assert installed == ["warehouse-a"]
    assert backend.installs == 1


def test_issues_and_robot_details_when_the_agent_reports_them() -> None:
    data = {
        "issues": {"odom": [{"reason": "unknown_type", "detail": "not in the store"}, "junk"], "x": "junk"},
        "robot_details": {
            "tb4_01": {"registered_at_ms": 1_700_000_000_500, "state": "lost", "explicit": True}
        },
    }
    snap = snapshot_from_agent(data, base_config())
    assert snap.issues == {"odom": [MappingIssue("unknown_type", "not in the store")]}
    robots = robots_from_agent(data, {"tb4_02": "tb4", "tb4_01": "tb4"})
    assert robots == [
        RobotStatus("tb4_01", "tb4", registered_at=1_700_000_000.5, state="lost", explicit=True),
        RobotStatus("tb4_02", "tb4"),
    ]
