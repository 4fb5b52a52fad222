"""fleetlink._native.ScannedBatch: what the uplink decides on, per topic, from a scanned batch."""

from __future__ import annotations

import pytest

from fleetlink._native import ScannedBatch
from fleetlink.wire import Batch, Record, decode_batch_head, encode_batch
from fleetlink.wire.records import single_object

pytestmark = pytest.mark.unit

FP_A, FP_B = b"\x01" * 8, b"\x02" * 8
SITE = (("fleetlink.site", b"s1"), ("fleetlink.edge", b"e1"))


def scanned(records: list[Record]) -> ScannedBatch:
    batch = Batch(site="s1", edge_id="e1", stream="durable", first_seq=records[0].seq, records=tuple(records))
    parsed = decode_batch_head(encode_batch(batch))
    return ScannedBatch.scan(parsed.body, parsed.groups_at)


Headers = tuple[tuple[str, bytes], ...]


def record(seq: int, topic: str, robot: bytes, fp: bytes = FP_A, *, headers: Headers = SITE) -> Record:
    return Record(topic, robot, single_object(fp, b"body"), (*headers, ("fleetlink.robot", robot)), seq=seq)


def test_topics_sum_up_every_robot_of_a_topic() -> None:
    batch = scanned(
        [
            record(10 + i, "fleet.imu" if i % 2 else "fleet.odom", b"r%d" % i, FP_A if i < 4 else FP_B)
            for i in range(6)
        ]
        + [Record("fleet.raw", b"r9", b"raw bytes", raw_value=True, seq=16)]
    )
    assert len(batch) == 7
    assert batch.last_seq() == 16
    assert batch.topics() == [
        ("fleet.odom", 3, 0, [FP_A, FP_B]),
        ("fleet.imu", 3, 0, [FP_A, FP_B]),
        ("fleet.raw", 1, 1, []),
    ]


def test_senders_are_one_per_topic_for_an_honest_edge() -> None:
    batch = scanned([record(1 + i, "fleet.imu", b"r%d" % i) for i in range(50)])
    assert batch.senders(["fleetlink.site", "fleetlink.edge"]) == [(0, list(SITE), 1)]


def test_a_record_naming_another_sender_gets_an_entry_of_its_own() -> None:
    forged = (("fleetlink.site", b"s2"), ("fleetlink.edge", b"e1"))
    batch = scanned(
        [
            record(1, "fleet.imu", b"r1"),
            record(2, "fleet.imu", b"r2", headers=forged),
            record(3, "fleet.imu", b"r3"),
        ]
    )
    senders = batch.senders(["fleetlink.site", "fleetlink.edge"])
    assert sorted(senders) == [(0, list(SITE), 1), (0, list(forged), 2)]


def test_acked_and_delivery_counts_are_per_topic() -> None:
    batch = scanned([record(1 + i, "a" if i < 3 else "b", b"r%d" % i) for i in range(5)])
    assert batch.acked_counts([]) == {"a": 3, "b": 2}
    assert batch.acked_counts([2, 4, 5]) == {"a": 2}
    # only the topics produced natively count; failures by record index
    assert batch.delivery_counts([1], [4]) == [("b", 1, 1)]
    assert batch.delivery_counts([0, 1], []) == [("a", 3, 0), ("b", 2, 0)]
