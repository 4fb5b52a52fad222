"""Edge health rules and the snapshot -> metrics bridge (clock injected)."""

from __future__ import annotations

import dataclasses

import pytest

from fleetlink.common.metrics import MetricsRecorder
from fleetlink.edge.admin.backend import BufferState, EdgeSnapshot, MappingCounts, MappingIssue, WanTotals
from fleetlink.edge.admin.health import HealthRules, assess
from fleetlink.edge.admin.telemetry import EdgeTelemetry
from fleetlink.edge.spool import SpoolStats

NOW_MS = 1_000_000


def stats(
    stream: str = "durable", *, nbytes: int = 0, depth: int = 0, blocked: int = 0, **counts: int
) -> SpoolStats:
    base = dict.fromkeys(
        (
            "appended",
            "acked",
            "dropped_oldest",
            "dropped_newest",
            "corrupt_skipped",
            "block_timeouts",
            "disk_full",
            "stale_acks",
            "fsyncs",
            "in_flight",
            "segments",
            "next_seq",
        ),
        0,
    )
    base.update(counts)
    return SpoolStats(
        stream=stream,
        bytes=nbytes,
        depth=depth,
        oldest_append_ms=NOW_MS - 4_000 if depth else None,
        blocked_appenders=blocked,
        **base,
    )


def buffer(*, nbytes: int = 0, depth: int = 0, blocked: int = 0) -> BufferState:
    return BufferState(stats=stats(nbytes=nbytes, depth=depth, blocked=blocked), capacity_bytes=1000)


@pytest.mark.parametrize(
    ("snapshot", "recent", "state", "reasons"),
    [
        (EdgeSnapshot(), {}, "ok", []),
        (EdgeSnapshot(buffers=(buffer(nbytes=799),)), {}, "ok", []),
        (
            EdgeSnapshot(buffers=(buffer(nbytes=800, depth=5),)),
            {},
            "degraded",
            [("spool", "durable", "spool_filling")],
        ),
        (
            EdgeSnapshot(buffers=(buffer(nbytes=100, blocked=2),)),
            {},
            "degraded",
            [("spool", "durable", "spool_full")],
        ),
        (EdgeSnapshot(wan_link_up=False), {}, "degraded", [("wan", "uplink", "wan_down")]),
        (EdgeSnapshot(wan_link_up=True), {"ir": 0}, "ok", []),
        (EdgeSnapshot(), {"ir": 3, "imu": 0}, "degraded", [("mapping", "ir", "dead_letters")]),
        (
            EdgeSnapshot(
                issues={"odom": [MappingIssue("unknown_type", "nav_msgs/msg/Odometry is not in the store")]}
            ),
            {},
            "degraded",
            [("mapping", "odom", "unknown_type")],
        ),
        (
            EdgeSnapshot(failure="spool unwritable", wan_link_up=False),
            {},
            "failed",
            [("process", "edge", "failed"), ("wan", "uplink", "wan_down")],
        ),
    ],
)
def test_health_rules(
    snapshot: EdgeSnapshot, recent: dict[str, int], state: str, reasons: list[tuple[str, str, str]]
) -> None:
    health = assess(snapshot, recent, now_ms=NOW_MS, robots=2)
    assert health.state == state
    assert [(p.component, p.subject, p.reason) for p in health.problems] == reasons
    assert health.extra["robots"] == 2


def test_spool_problem_says_how_full_and_how_old() -> None:
    health = assess(EdgeSnapshot(buffers=(buffer(nbytes=900, depth=9),)), {}, now_ms=NOW_MS, robots=0)
    assert health.problems[0].detail == "90% of 1000 bytes used; the oldest record is 4.0 s old"
    assert health.extra["spool_fill"] == {"durable": 0.9}


def test_unacknowledged_spool_damage_degrades_and_says_what() -> None:
    damaged = BufferState(stats=stats(damage_unacknowledged=2), capacity_bytes=1000)
    finding = {"reason": "segment_missing", "file": "00000000000000001150.seg", "records": 1149}
    other = {"reason": "corrupt", "file": "00000000000000003000.seg", "records": 1}
    health = assess(
        EdgeSnapshot(buffers=(damaged,), spool_damage={"durable": [finding, other]}),
        {},
        now_ms=NOW_MS,
        robots=0,
    )
    assert health.state == "degraded"
    ((component, subject, reason, detail),) = [
        (p.component, p.subject, p.reason, p.detail) for p in health.problems
    ]
    assert (component, subject, reason) == ("spool", "durable", "spool_damage")
    assert detail.startswith(
        "2 damage finding(s) (1150 record(s) lost); first: segment_missing in 00000000000000001150.seg"
    )
    assert "POST /spool/damage/acknowledge" in detail
    acknowledged = BufferState(stats=stats(), capacity_bytes=1000)
    assert assess(EdgeSnapshot(buffers=(acknowledged,)), {}, now_ms=NOW_MS, robots=0).state == "ok"


def test_threshold_is_a_rule() -> None:
    snapshot = EdgeSnapshot(buffers=(buffer(nbytes=500),))
    assert (
        assess(snapshot, {}, now_ms=NOW_MS, robots=0, rules=HealthRules(spool_fill=0.5)).state == "degraded"
    )


class Clock:
    def __init__(self) -> None:
        self.now = NOW_MS / 1000

    def __call__(self) -> float:
        return self.now


def test_telemetry_reports_increments_and_gauges() -> None:
    rec, clock = MetricsRecorder(), Clock()
    telemetry = EdgeTelemetry(rec, clock=clock)
    counts = MappingCounts(
        received=10,
        emitted=4,
        dropped=5,
        dead_lettered=1,
        type_mismatch=0,
        stages={"throttle": {"emitted": 4, "dropped": 5, "late": 0, "errors": 1}},
    )
    snap = EdgeSnapshot(
        mappings={"ir": counts},
        buffers=(
            BufferState(
                stats(nbytes=300, depth=3, appended=12, dropped_oldest=2, lost_missing=0),
                capacity_bytes=1000,
                appended_bytes=1200,
            ),
        ),
        wan={
            "durable": WanTotals(
                batches_sent=3,
                records_sent=12,
                bytes_sent=900,
                batches_acked=2,
                records_acked=9,
                batches_retried=1,
                in_flight=1,
            )
        },
        wan_link_up=True,
        sequence_gaps={"/tb4_01/ir": 2},
        unmapped={"/tb4_09/ir": 4},
        lost_before_spool={"tb4_01": {"/tb4_01/ir": 7}},
    )
    health = telemetry.observe(snap, robots=2)
    assert health.state == "degraded"  # one dead letter just now
    again = dataclasses.replace(snap, mappings={"ir": dataclasses.replace(counts, received=15, emitted=6)})
    clock.now += 61
    assert telemetry.observe(again, robots=2).state == "ok"  # the dead letter is more than a minute old
    expected = {
        ("fleetlink_mapping_received", ("ir",)): 15,
        ("fleetlink_mapping_emitted", ("ir",)): 6,
        ("fleetlink_mapping_dropped", ("ir", "pipeline")): 5,
        ("fleetlink_mapping_dead_lettered", ("ir", "")): 1,
        ("fleetlink_stage_emitted", ("ir", "throttle")): 4,
        ("fleetlink_stage_dropped", ("ir", "throttle", "dropped")): 5,
        ("fleetlink_stage_dropped", ("ir", "throttle", "error")): 1,
        ("fleetlink_spool_appended_records", ("durable",)): 12,
        ("fleetlink_spool_appended_bytes", ("durable",)): 1200,
        ("fleetlink_spool_dropped_records", ("durable", "dropped_oldest")): 2,
        ("fleetlink_spool_bytes", ("durable",)): 300,
        ("fleetlink_spool_capacity_bytes", ("durable",)): 1000,
        ("fleetlink_spool_depth_records", ("durable",)): 3,
        ("fleetlink_spool_in_flight_records", ("durable",)): 0,
        ("fleetlink_spool_oldest_age_seconds", ("durable",)): 65.0,
        ("fleetlink_wan_sent_batches", ()): 3,
        ("fleetlink_wan_sent_records", ()): 12,
        ("fleetlink_wan_sent_bytes", ()): 900,
        ("fleetlink_wan_acked_batches", ()): 2,
        ("fleetlink_wan_acked_records", ()): 9,
        ("fleetlink_wan_failures", ("retry",)): 1,
        ("fleetlink_wan_in_flight_batches", ()): 1,
        ("fleetlink_wan_link_up", ()): 1,
        ("fleetlink_robots_registered", ()): 2,
        ("fleetlink_sequence_gaps", ("/tb4_01/ir",)): 2,
        ("fleetlink_unmapped_samples", ("/tb4_09/ir",)): 4,
        ("fleetlink_lost_before_spool", ("tb4_01", "/tb4_01/ir")): 7,
        ("fleetlink_spool_damage_unacknowledged", ("durable",)): 0,
        ("fleetlink_intake_queued_samples", ()): 0.0,
        ("fleetlink_intake_lag_seconds", ()): 0.0,
        ("fleetlink_memory_resident_bytes", ()): 0.0,
        ("fleetlink_memory_bound_bytes", ()): 0.0,
        ("fleetlink_health", ("ok",)): 1,
        ("fleetlink_health", ("degraded",)): 0,
        ("fleetlink_health", ("failed",)): 0,
    }
    assert rec.series() == expected


def test_a_rebuilt_pipeline_does_not_count_backwards() -> None:
    rec = MetricsRecorder()
    telemetry = EdgeTelemetry(rec, clock=Clock())
    for received in (10, 4, 6):  # 10 -> 4: the mapping was changed and its counters started again
        telemetry.observe(EdgeSnapshot(mappings={"ir": MappingCounts(received=received)}), robots=0)
    assert rec.value("fleetlink_mapping_received", mapping="ir") == 16
