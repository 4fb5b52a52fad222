"""fleetlink.console.status: an edge's spool, WAN and topic counters for the console."""

from __future__ import annotations

from fleetlink.console.status import site_status
from fleetlink.edge.admin.backend import BufferState, EdgeSnapshot, WanTotals
from fleetlink.edge.spool import SpoolStats


def stats(stream: str, **values: int | None) -> SpoolStats:
    base: dict[str, int | None] = {
        "appended": 0,
        "acked": 0,
        "dropped_oldest": 0,
        "dropped_newest": 0,
        "corrupt_skipped": 0,
        "block_timeouts": 0,
        "disk_full": 0,
        "stale_acks": 0,
        "fsyncs": 0,
        "bytes": 0,
        "depth": 0,
        "in_flight": 0,
        "oldest_append_ms": None,
        "segments": 1,
        "next_seq": 0,
    }
    base.update(values)
    return SpoolStats(stream=stream, **base)  # type: ignore[arg-type]


def test_from_the_snapshot_and_the_agent_counters() -> None:
    snapshot = EdgeSnapshot(
        buffers=(
            BufferState(
                stats(
                    "durable",
                    bytes=2_500,
                    depth=12,
                    in_flight=4,
                    oldest_append_ms=9_000,
                    appended=40,
                    acked=28,
                    dropped_oldest=1,
                    dropped_newest=2,
                ),
                10_000,
            ),
            BufferState(stats("memory"), 0),
        ),
        wan={
            "durable": WanTotals(
                batches_sent=5, batches_acked=4, records_acked=28, batches_retried=1, in_flight=1
            )
        },
        wan_link_up=False,
        sequence_gaps={"/tb4_01/imu": 3},
    )
    raw = {
        "streams": {"durable": {"sender": {"healthy": False, "outage_s": 2.5, "last_error": "timeout"}}},
        "subscriptions": {
            "/tb4_01/imu": {"received": 100, "missing": 3, "type": "sensor_msgs/msg/Imu"},
            "/tb4_01/ir": "not a dict",
        },
    }
    status = site_status(snapshot, raw, now_ms=10_500)
    assert status["wan_link_up"] is False
    assert status["streams"] == [
        {
            "stream": "durable",
            "depth": 12,
            "bytes": 2_500,
            "capacity_bytes": 10_000,
            "fill": 0.25,
            "oldest_age_s": 1.5,
            "in_flight": 4,
            "appended": 40,
            "acked": 28,
            "dropped": 3,
            "blocked_appenders": 0,
        },
        {
            "stream": "memory",
            "depth": 0,
            "bytes": 0,
            "capacity_bytes": 0,
            "fill": None,
            "oldest_age_s": 0.0,
            "in_flight": 0,
            "appended": 0,
            "acked": 0,
            "dropped": 0,
            "blocked_appenders": 0,
        },
    ]
    assert status["wan"] == {
        "durable": {
            "batches_sent": 5,
            "batches_acked": 4,
            "records_acked": 28,
            "batches_retried": 1,
            "in_flight": 1,
            "healthy": False,
            "outage_s": 2.5,
            "last_error": "timeout",
        }
    }
    assert status["topics"]["/tb4_01/imu"] == {
        "received": 100,
        "delivered": 0,
        "rejected": 0,
        "gaps": 0,
        "missing": 3,
        "duplicates": 0,
    }
    assert status["topics"]["/tb4_01/ir"]["received"] == 0
    assert status["sequence_gaps"] == {"/tb4_01/imu": 3}


def test_without_agent_counters() -> None:
    status = site_status(EdgeSnapshot(), None, now_ms=0)
    assert status == {
        "wan_link_up": None,
        "streams": [],
        "wan": {},
        "topics": {},
        "sequence_gaps": {},
        "failure": None,
    }
