"""RecordMaker: ROS samples -> Kafka records (fast path, templates, stages, dead letters)."""

from __future__ import annotations

import hashlib
import io
from collections.abc import Sequence
from functools import cache
from typing import Any

import fastavro
import pytest
from rosbags.rosbag2 import Reader

from fleetlink.edge.mapping import MappingSpec, MappingTable, RobotTypeSpec
from fleetlink.edge.runtime.outgoing import Outgoing
from fleetlink.edge.runtime.records import RecordMaker
from fleetlink.edge.runtime.types import TypeStoreCodecs
from fleetlink.edge.stages import AggregateSpec, FilterSpec, ProjectSpec, ThrottleSpec
from fleetlink.roswire import cdr
from fleetlink.roswire.errors import AttachmentError, KeyParseError, PayloadError, RoswireError
from fleetlink.roswire.subscriber import RosSample
from fleetlink.schemas.single_object import fingerprint
from fleetlink.schemas.typestore import load_typestore
from fleetlink.wire import Record, split_single_object
from tests.paths import HUSKY as HUSKY_BAG

BAG = HUSKY_BAG
IMU = "sensor_msgs/msg/Imu"
STRING = "std_msgs/msg/String"
IMU_HASH = "RIHS01_" + "7d" * 32
STAMP_NS = 1_700_000_000_123_456_789


@cache
def codecs() -> TypeStoreCodecs:
    return TypeStoreCodecs(load_typestore("jazzy"), "jazzy")


@cache
def imu_payloads() -> tuple[bytes, ...]:
    out = []
    with Reader(BAG) as reader:
        conns = [c for c in reader.connections if c.topic == "/imu/data"]
        for _, _, raw in reader.messages(connections=conns):
            out.append(bytes(raw))
            if len(out) == 40:
                break
    return tuple(out)


def sample(
    topic: str, payload: bytes, *, typename: str = IMU, seq: int | None = 1, stamp_ns: int | None = STAMP_NS
) -> RosSample:
    return RosSample(
        topic=topic,
        typename=typename,
        type_hash=IMU_HASH,
        payload=payload,
        seq=seq,
        source_ts_ns=stamp_ns,
        gid=b"\x01" * 16,
        key=f"0{topic}/dds/{IMU_HASH}",
        received_ns=STAMP_NS + 5_000_000,
    )


Made = tuple[RecordMaker, MappingTable, dict[bytes, str]]


def maker_for(
    mappings: Sequence[MappingSpec] = (),
    robot_types: Sequence[RobotTypeSpec] = (),
    robots: Sequence[str] = (),
    **kwargs: Any,
) -> Made:
    table = MappingTable(robot_types, mappings)
    for robot in robots:
        table.add_robot(robot)
    seen: dict[bytes, str] = {}
    maker = RecordMaker(
        site="warehouse-a",
        edge_id="edge-1",
        match=table.match,
        types=codecs(),
        dead_letter_topic="fleetlink.dead-letter",
        on_schema=seen.__setitem__,
        **kwargs,
    )
    return maker, table, seen


def read_value(record: Record, schemas: dict[bytes, str]) -> dict[str, Any]:
    fp, body = split_single_object(record.value)
    schema = fastavro.parse_schema(__import__("json").loads(schemas[fp]))
    datum = fastavro.schemaless_reader(io.BytesIO(bytes(body)), schema, None)
    assert isinstance(datum, dict)
    return datum


def headers(record: Record) -> dict[str, str]:
    return {k: v.decode() for k, v in record.headers}


HUSKY = RobotTypeSpec(
    "husky", "/husky_*", (MappingSpec(name="imu", source="/{robot}/imu/data", topic="fleet.imu"),)
)


def test_fast_path_record_shape() -> None:
    maker, _, seen = maker_for(robot_types=[HUSKY], robots=["husky_1"])
    payload = imu_payloads()[0]
    out = maker.make(sample("/husky_1/imu/data", payload, seq=7), now_ns=0)
    assert len(out) == 1
    outgoing = out[0]
    assert outgoing.delivery == "at_least_once"
    record = outgoing.record
    codec = codecs().codec(IMU)
    assert record.kafka_topic == "fleet.imu"
    assert record.key == b"husky_1"
    assert not record.raw_value
    assert record.value == b"\xc3\x01" + fingerprint(codec.schema) + codec.cdr_to_avro(payload)
    assert record.timestamp_ms == STAMP_NS // 1_000_000
    assert headers(record) == {
        "fleetlink.source_topic": "/husky_1/imu/data",
        "fleetlink.ros_type": IMU,
        "fleetlink.type_hash": IMU_HASH,
        "fleetlink.site": "warehouse-a",
        "fleetlink.edge": "edge-1",
        "fleetlink.robot": "husky_1",
        "fleetlink.seq": "7",
        "fleetlink.mapping": "imu",
    }
    assert seen[fingerprint(codec.schema)] is not None
    assert read_value(record, seen) == codec.decode(payload)
    assert maker.counters["imu"].as_dict() == {
        "received": 1,
        "emitted": 1,
        "dropped": 0,
        "dead_lettered": 0,
        "type_mismatch": 0,
    }


@pytest.mark.parametrize(
    ("seq", "stamp_ns", "expect_seq", "expect_ms"),
    [
        (None, STAMP_NS, None, STAMP_NS // 1_000_000),
        (3, None, "3", (STAMP_NS + 5_000_000) // 1_000_000),  # no source stamp: the receive time
        (0, 0, "0", (STAMP_NS + 5_000_000) // 1_000_000),
    ],
)
def test_seq_header_and_timestamp_fallback(
    seq: int | None, stamp_ns: int | None, expect_seq: str | None, expect_ms: int
) -> None:
    maker, _, _ = maker_for(robot_types=[HUSKY], robots=["husky_1"])
    made = sample("/husky_1/imu/data", imu_payloads()[0], seq=seq, stamp_ns=stamp_ns)
    record = maker.make(made, 0)[0].record
    assert headers(record).get("fleetlink.seq") == expect_seq
    assert record.timestamp_ms == expect_ms


def test_many_to_one_and_many_to_many() -> None:
    robot_type = RobotTypeSpec(
        "husky", "/husky_*", (MappingSpec(name="imu", source="/{robot}/imu/data", topic="fleet.imu"),)
    )
    site = [
        MappingSpec(
            name="raw",
            source="/{robot}/{sensor}/data",
            topic="fleet.raw.{sensor}",
            key="{robot}-{sensor}",
            delivery="best_effort",
        )
    ]
    maker, _, _ = maker_for(site, [robot_type], robots=["husky_1", "husky_2"])
    payload = imu_payloads()[0]
    made = [
        (o.delivery, o.record.kafka_topic, o.record.key)
        for robot in ("husky_1", "husky_2", "other_3")
        for o in maker.make(sample(f"/{robot}/imu/data", payload), 0)
    ]
    assert made == [
        ("best_effort", "fleet.raw.imu", b"husky_1-imu"),
        ("at_least_once", "fleet.imu", b"husky_1"),
        ("best_effort", "fleet.raw.imu", b"husky_2-imu"),
        ("at_least_once", "fleet.imu", b"husky_2"),
        ("best_effort", "fleet.raw.imu", b"other_3-imu"),
    ]


def test_a_sample_no_mapping_takes_is_counted_not_lost_silently() -> None:
    maker, table, _ = maker_for(robot_types=[HUSKY], robots=["husky_1"])
    payload = imu_payloads()[0]
    assert maker.make(sample("/husky_2/imu/data", payload), 0) == []  # husky_2 not registered (yet)
    assert maker.make(sample("/husky_2/imu/data", payload), 0) == []
    assert len(maker.make(sample("/husky_1/imu/data", payload), 0)) == 1
    assert maker.unmapped == {"/husky_2/imu/data": 2}
    table.add_robot("husky_2")
    assert len(maker.make(sample("/husky_2/imu/data", payload), 0)) == 1
    assert maker.unmapped == {"/husky_2/imu/data": 2}


@pytest.mark.parametrize(
    ("text", "topic", "stage"),
    [
        ("zone_a", "fleet.tasks.zone_a", None),
        ("zone.b-2", "fleet.tasks.zone.b-2", None),
        ("not a topic", None, "map"),
        ("zone/1", None, "map"),
    ],
)
def test_one_to_many_by_message_field(text: str, topic: str | None, stage: str | None) -> None:
    spec = MappingSpec(name="tasks", source="/{robot}/task", topic="fleet.tasks.{msg.data}")
    maker, _, seen = maker_for([spec])
    payload = cdr.encode_string(text)
    out = maker.make(sample("/tb4_01/task", payload, typename=STRING), 0)
    assert len(out) == 1
    record = out[0].record
    if topic is not None:
        assert record.kafka_topic == topic
        assert record.key == b"tb4_01"
        assert read_value(record, seen) == {"data": text}
    else:
        assert record.kafka_topic == "fleetlink.dead-letter"
        assert record.raw_value
        assert record.value == payload
        assert headers(record)["fleetlink.dlq.stage"] == stage
        assert headers(record)["fleetlink.dlq.topic"] == "fleet.tasks.{msg.data}"
        assert maker.counters["tasks"].dead_lettered == 1


def test_key_from_message_field() -> None:
    spec = MappingSpec(name="k", source="/{robot}/task", topic="fleet.t", key="{msg.data}")
    maker, _, _ = maker_for([spec])
    record = maker.make(sample("/tb4_01/task", cdr.encode_string("order-17"), typename=STRING), 0)[0].record
    assert record.key == b"order-17"


@pytest.mark.parametrize(
    ("payload", "reason_part"),
    [
        (b"\x00\x01\x00\x00\x01", "Imu"),  # truncated
        (b"\x00\x07\x00\x00" + b"\x00" * 300, "encapsulation"),  # unknown encapsulation
    ],
)
def test_undecodable_cdr_is_dead_lettered_and_the_next_flows(payload: bytes, reason_part: str) -> None:
    maker, _, _ = maker_for(robot_types=[HUSKY], robots=["husky_1"])
    bad = maker.make(sample("/husky_1/imu/data", payload, seq=4), 0)
    good = maker.make(sample("/husky_1/imu/data", imu_payloads()[1], seq=5), 0)
    assert len(bad) == 1
    record = bad[0].record
    h = headers(record)
    assert record.kafka_topic == "fleetlink.dead-letter"
    assert record.raw_value
    assert record.value == payload
    assert record.key == b"husky_1"
    assert h["fleetlink.dlq.stage"] == "decode"
    assert reason_part in h["fleetlink.dlq.reason"]
    assert h["fleetlink.dlq.size"] == str(len(payload))
    assert h["fleetlink.ros_key"] == f"0/husky_1/imu/data/dds/{IMU_HASH}"
    assert h["fleetlink.dlq.topic"] == "fleet.imu"
    assert h["fleetlink.seq"] == "4"
    assert [o.record.kafka_topic for o in good] == ["fleet.imu"]
    assert maker.counters["imu"].as_dict()["dead_lettered"] == 1
    assert maker.counters["imu"].as_dict()["emitted"] == 1


def test_unknown_type_is_dead_lettered_once_then_counted() -> None:
    maker, _, _ = maker_for([MappingSpec(name="all", source="/{robot}/{topic}", topic="fleet.{topic}")])
    first = maker.make(sample("/r1/x", b"\x00\x01\x00\x00abcd", typename="nobody_msgs/msg/Nothing"), 0)
    again = [
        maker.make(sample("/r1/x", b"\x00\x01\x00\x00abcd", typename="nobody_msgs/msg/Nothing"), 0)
        for _ in range(3)
    ]
    assert len(first) == 1
    assert headers(first[0].record)["fleetlink.dlq.stage"] == "decode"
    assert "nobody_msgs/msg/Nothing" in headers(first[0].record)["fleetlink.dlq.reason"]
    assert again == [[], [], []]
    assert maker.unknown_type_samples == 4
    assert maker.counters["all"].as_dict() == {
        "received": 4,
        "emitted": 0,
        "dropped": 3,
        "dead_lettered": 1,
        "type_mismatch": 0,
    }


def test_declared_type_mismatch_is_counted_not_mapped() -> None:
    maker, _, _ = maker_for([MappingSpec(name="imu", source="/{robot}/imu", topic="fleet.imu", ros_type=IMU)])
    assert maker.make(sample("/r1/imu", cdr.encode_string("x"), typename=STRING), 0) == []
    assert maker.counters["imu"].type_mismatch == 1


@pytest.mark.parametrize(
    ("error", "raw", "key"),
    [
        (
            PayloadError("0/r1/imu/x/y", IMU, b"garbage!", "sample has no rmw_zenoh attachment"),
            b"garbage!",
            "0/r1/imu/x/y",
        ),
        (AttachmentError(b"\x01\x02", "length 2 is neither 33 (v2) nor 77 (v1)"), b"\x01\x02", "/r1/imu"),
        (
            AttachmentError(
                b"\x01\x02",
                "length 2 is neither 33 (v2) nor 77 (v1)",
                key="0/r1/imu/x/y",
                payload=b"the sample",
            ),
            b"the sample",
            "0/r1/imu/x/y",
        ),
        (KeyParseError("0/r1/imu/bad", "needs at least 4 chunks"), b"", "0/r1/imu/bad"),
    ],
)
def test_rejected_samples_become_dead_letters(error: RoswireError, raw: bytes, key: str) -> None:
    maker, _, _ = maker_for(
        [MappingSpec(name="imu", source="/{robot}/imu", topic="fleet.imu", delivery="best_effort")]
    )
    out = maker.rejected_sample("/r1/imu", error, STAMP_NS)
    assert len(out) == 1
    assert out[0].delivery == "best_effort"
    record = out[0].record
    h = headers(record)
    assert (record.kafka_topic, record.key, record.value, record.raw_value) == (
        "fleetlink.dead-letter",
        b"r1",
        raw,
        True,
    )
    assert h["fleetlink.dlq.stage"] == "receive"
    assert h["fleetlink.ros_key"] == key
    assert h["fleetlink.dlq.reason"] == str(error)
    assert h["fleetlink.edge"] == "edge-1"
    assert maker.rejected == 1


def test_rejected_sample_of_unmapped_topic_goes_durable_without_key() -> None:
    maker, _, _ = maker_for()
    out = maker.rejected_sample("/x", PayloadError("0/x/a/b", None, b"zz", "bad"), STAMP_NS)
    assert out[0].delivery == "at_least_once"
    assert out[0].record.key is None
    assert "fleetlink.mapping" not in headers(out[0].record)


def test_filter_and_throttle_keep_the_fast_encoder() -> None:
    spec = MappingSpec(
        name="imu",
        source="/{robot}/imu/data",
        topic="fleet.imu",
        stages=(
            FilterSpec(type="filter", expr="linear_acceleration.z > -1000"),
            ThrottleSpec(type="throttle", hz=10, keep="first"),
        ),
    )
    maker, _, seen = maker_for([spec])
    payloads = imu_payloads()[:5]
    out: list[Outgoing] = []
    for i, payload in enumerate(payloads):  # 5 samples within one 100 ms period: one passes
        out += maker.make(sample("/r1/imu/data", payload, seq=i + 1), now_ns=1_000_000_000 + i * 1_000_000)
    codec = codecs().codec(IMU)
    assert len(out) == 1
    assert out[0].record.value == b"\xc3\x01" + fingerprint(codec.schema) + codec.cdr_to_avro(payloads[0])
    assert headers(out[0].record)["fleetlink.seq"] == "1"
    assert set(seen) == {fingerprint(codec.schema)}
    assert maker.counters["imu"].as_dict() == {
        "received": 5,
        "emitted": 1,
        "dropped": 4,
        "dead_lettered": 0,
        "type_mismatch": 0,
    }
    assert maker.stage_counters()["imu"]["throttle"]["dropped"] == 4


def test_project_uses_a_derived_schema() -> None:
    spec = MappingSpec(
        name="acc",
        source="/{robot}/imu/data",
        topic="fleet.acc",
        stages=(ProjectSpec(type="project", fields=["linear_acceleration.z", "header.stamp"], flatten=True),),
    )
    maker, _, seen = maker_for([spec])
    payload = imu_payloads()[2]
    record = maker.make(sample("/r1/imu/data", payload), 0)[0].record
    fp, _ = split_single_object(record.value)
    codec = codecs().codec(IMU)
    assert fp != fingerprint(codec.schema)
    assert fingerprint(seen[fp]) == fp
    full = codec.decode(payload)
    assert read_value(record, seen) == {
        "linear_acceleration_z": full["linear_acceleration"]["z"],
        "header_stamp": full["header"]["stamp"],
    }
    assert "fleetlink.seq" not in headers(record)  # a new value made by a stage


def test_aggregate_windows_leave_on_tick() -> None:
    spec = MappingSpec(
        name="agg",
        source="/{robot}/imu/data",
        topic="fleet.imu_1s",
        stages=(
            AggregateSpec.model_validate(
                {
                    "type": "aggregate",
                    "window": "1s",
                    "idle_timeout": "500ms",
                    "fields": ["linear_acceleration.x"],
                    "ops": ["count", "max"],
                }
            ),
        ),
    )
    maker, _, seen = maker_for([spec])
    for i, payload in enumerate(imu_payloads()[:10]):
        assert maker.make(sample("/r1/imu/data", payload, stamp_ns=5_000_000_000 + i * 10_000_000), 0) == []
    assert maker.tick(100_000_000) == []
    out = maker.tick(2_000_000_000)  # idle for longer than idle_timeout: the window is emitted
    assert len(out) == 1
    record = out[0].record
    value = read_value(record, seen)
    assert (record.kafka_topic, record.key) == ("fleet.imu_1s", b"r1")
    assert (value["robot"], value["count"]) == ("r1", 10)
    assert record.timestamp_ms == 6_000
    assert headers(record)["fleetlink.mapping"] == "agg"


def test_stage_that_does_not_fit_the_type_is_reported_once() -> None:
    spec = MappingSpec(
        name="bad",
        source="/{robot}/imu/data",
        topic="fleet.bad",
        stages=(ProjectSpec(type="project", fields=["no_such_field"]),),
    )
    maker, _, _ = maker_for([spec])
    first = maker.make(sample("/r1/imu/data", imu_payloads()[0]), 0)
    second = maker.make(sample("/r1/imu/data", imu_payloads()[1]), 0)
    assert [headers(o.record)["fleetlink.dlq.stage"] for o in first] == ["setup"]
    assert "no_such_field" in headers(first[0].record)["fleetlink.dlq.reason"]
    assert second == []
    assert maker.counters["bad"].dropped == 1


def test_oversized_value_becomes_a_dead_letter_with_a_reference() -> None:
    maker, _, _ = maker_for(
        robot_types=[HUSKY], robots=["husky_1"], max_value_bytes=100, max_dead_letter_bytes=50
    )
    payload = imu_payloads()[0]
    out = maker.make(sample("/husky_1/imu/data", payload), 0)
    record = out[0].record
    h = headers(record)
    assert record.kafka_topic == "fleetlink.dead-letter"
    assert record.value == b""
    assert h["fleetlink.dlq.stage"] == "size"
    assert h["fleetlink.dlq.size"] == str(len(payload))
    assert h["fleetlink.dlq.sha256"] == hashlib.sha256(payload).hexdigest()
    assert h["fleetlink.dlq.truncated"] == "true"
    assert h["fleetlink.dlq.topic"] == "fleet.imu"
    assert "exceeds" in h["fleetlink.dlq.reason"]


def test_removed_robot_stops_mapping() -> None:
    maker, table, _ = maker_for(robot_types=[HUSKY], robots=["husky_1"])
    assert len(maker.make(sample("/husky_1/imu/data", imu_payloads()[0]), 0)) == 1
    table.remove_robot("husky_1")
    assert maker.make(sample("/husky_1/imu/data", imu_payloads()[0]), 0) == []
