"""A command record -> decoded value -> forwards (ids, leases, keys); status record values."""

from __future__ import annotations

import io
import struct
from typing import Any

import fastavro
import pytest

from fleetlink.schemas.errors import RegistryError
from fleetlink.schemas.registry import RegistryUnavailableError
from fleetlink.schemas.single_object import confluent_frame, fingerprint
from fleetlink.uplink.commands.decode import CommandDecoder
from fleetlink.uplink.commands.errors import RegistryUnreachableError, UndecodableValueError
from fleetlink.uplink.commands.mapping import CommandMapping
from fleetlink.uplink.commands.plan import COMMAND_ID_HEADER, CommandRecord, command_id, plan
from fleetlink.uplink.commands.status_records import STATUS_SCHEMA, status_value
from fleetlink.wire.commands import StatusEvent

SCHEMA: dict[str, Any] = {
    "type": "record",
    "name": "Task",
    "namespace": "t",
    "fields": [{"name": "robot_id", "type": "string"}, {"name": "speed", "type": "int"}],
}


class Registry:
    def __init__(self, schemas: dict[int, dict[str, Any]], *, down: bool = False) -> None:
        self.schemas = schemas
        self.down = down
        self.calls = 0

    def schema_by_id(self, schema_id: int) -> dict[str, Any]:
        self.calls += 1
        if self.down:
            raise RegistryUnavailableError(f"id {schema_id}", "connection refused")
        if schema_id not in self.schemas:
            raise RegistryError(f"id {schema_id}", "HTTP 404 (error 40403): schema not found")
        return self.schemas[schema_id]


def body(datum: dict[str, Any], schema: dict[str, Any] = SCHEMA) -> bytes:
    out = io.BytesIO()
    fastavro.schemaless_writer(out, fastavro.parse_schema(schema), datum)
    return out.getvalue()


GOOD = confluent_frame(7, body({"robot_id": "tb4_03", "speed": 2}))


def test_decode_reads_the_record_and_caches_the_writer() -> None:
    registry = Registry({7: SCHEMA})
    decoder = CommandDecoder(registry)
    first = decoder.decode(GOOD)
    assert first.record == {"robot_id": "tb4_03", "speed": 2}
    assert first.writer.fingerprint == fingerprint(SCHEMA)
    assert first.body == GOOD[5:]
    decoder.decode(GOOD)
    assert registry.calls == 1


@pytest.mark.parametrize(
    ("value", "reason"),
    [
        (None, "tombstone"),
        (b"", "too short"),
        (b"garbage!", "magic byte 0x67"),
        (b"\x01" + GOOD[1:], "magic byte 0x01"),
        (confluent_frame(99, b"\x00"), "unknown schema id 99"),
        (GOOD[:-1], "does not match schema id 7"),
        (GOOD + b"\x00", "1 bytes left over"),
        (confluent_frame(8, b""), "schema id 8 is not a record schema"),
        (confluent_frame(9, b""), "schema id 9 is not usable Avro"),
    ],
)
def test_undecodable_values(value: bytes | None, reason: str) -> None:
    decoder = CommandDecoder(Registry({7: SCHEMA, 8: {"type": "null"}, 9: {"type": "nonsense"}}))
    with pytest.raises(UndecodableValueError, match=reason) as info:
        decoder.decode(value)
    assert info.value.raw == value


def test_an_unreachable_registry_is_not_the_records_fault() -> None:
    with pytest.raises(RegistryUnreachableError, match="connection refused"):
        CommandDecoder(Registry({}, down=True)).decode(GOOD)


def record(**fields: Any) -> CommandRecord:
    base: dict[str, Any] = {
        "topic": "fleet.tasks",
        "partition": 2,
        "offset": 41,
        "key": b"tb4_01",
        "value": GOOD,
        "timestamp_ms": 1_700_000_000_000,
    }
    return CommandRecord(**{**base, **fields})


@pytest.mark.parametrize(
    ("headers", "expected"),
    [
        ((), "fleet.tasks:2:41"),
        (((COMMAND_ID_HEADER, b"tb4_02-failed-1700"),), "tb4_02-failed-1700"),
        (((COMMAND_ID_HEADER, b"  "),), "fleet.tasks:2:41"),
        ((("other", b"x"), (COMMAND_ID_HEADER, b"id-2")), "id-2"),
    ],
)
def test_command_id(headers: tuple[tuple[str, bytes], ...], expected: str) -> None:
    assert command_id(record(headers=headers)) == expected


MAPPING = CommandMapping.model_validate(
    {
        "name": "task",
        "from": "fleet.tasks",
        "to": "/{msg.robot_id}/task",
        "type": "t/msg/Task",
        "repeat": {"period": "500ms", "lease": "8s"},
        "qos": {"depth": 1},
    }
)


def test_plan_for_a_robot_with_a_known_site() -> None:
    decoded = CommandDecoder(Registry({7: SCHEMA})).decode(GOOD)
    [forward] = plan(record(), MAPPING, decoded, now_ms=1_700_000_001_000, site_of={"tb4_03": "a"}.get)
    env = forward.envelope
    assert (forward.site, forward.key_expr) == ("a", "fleetlink/a/command/tb4_03/task")
    assert (env.robot, env.ros_topic, env.ros_type, env.mapping) == (
        "tb4_03",
        "/tb4_03/task",
        "t/msg/Task",
        "task",
    )
    assert (env.issued_at_ms, env.lease_until_ms, env.period_ms) == (
        1_700_000_000_000,
        1_700_000_008_000,
        500,
    )
    assert (env.command_id, env.order, env.source) == ("fleet.tasks:2:41", 41, "fleet.tasks:2:41")
    writer = decoded.writer
    assert (env.schema_fp, env.body, env.schema) == (writer.fingerprint, decoded.body, writer.text)
    assert env.qos == "::,1:,:,:,,"


def test_plan_for_an_unknown_robot_queries_every_site_and_without_timestamp_leases_from_now() -> None:
    decoded = CommandDecoder(Registry({7: SCHEMA})).decode(GOOD)
    [forward] = plan(record(timestamp_ms=-1), MAPPING, decoded, now_ms=5_000, site_of=lambda _r: None)
    assert (forward.site, forward.key_expr) == (None, "fleetlink/*/command/tb4_03/task")
    assert (forward.envelope.issued_at_ms, forward.envelope.lease_until_ms) == (5_000, 13_000)


def test_broadcast_plans_one_forward_per_registered_robot() -> None:
    broadcast = CommandMapping.model_validate(
        {"name": "all", "from": "fleet.all", "to": "/{robot}/cmd", "type": "t/msg/Task", "broadcast": True}
    )
    decoded = CommandDecoder(Registry({7: SCHEMA})).decode(GOOD)
    forwards = plan(
        record(), broadcast, decoded, now_ms=0, site_of={"r1": "a", "r2": "b"}.get, registered=["r2", "r1"]
    )
    assert [(f.key_expr, f.envelope.ros_topic) for f in forwards] == [
        ("fleetlink/a/command/r1/all", "/r1/cmd"),
        ("fleetlink/b/command/r2/all", "/r2/cmd"),
    ]
    assert {f.envelope.command_id for f in forwards} == {"fleet.tasks:2:41"}


def test_status_record_value_reads_back_with_its_schema() -> None:
    event = StatusEvent(
        "c1", "tb4_01", "/tb4_01/cmd", "superseded", 1_700_000_000_123, "a", "superseded by c2"
    )
    value = status_value(42, event)
    assert value[:5] == b"\x00" + struct.pack(">I", 42)
    datum = fastavro.schemaless_reader(io.BytesIO(value[5:]), fastavro.parse_schema(STATUS_SCHEMA), None)
    assert isinstance(datum, dict)
    assert datum["status"] == "superseded"
    assert (datum["command_id"], datum["robot"], datum["site"], datum["detail"]) == (
        "c1",
        "tb4_01",
        "a",
        "superseded by c2",
    )
    assert int(datum["at"].timestamp() * 1000) == 1_700_000_000_123
