"""The processing thread: samples in, records appended per delivery class, full buffers counted."""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from functools import cache

import pytest

from fleetlink.edge.claim_check import Claimed, ClaimJob
from fleetlink.edge.errors import SpoolFullError
from fleetlink.edge.mapping import MappingSpec, MappingTable, RobotTypeSpec
from fleetlink.edge.runtime.early import EarlySamples
from fleetlink.edge.runtime.intake import Intake
from fleetlink.edge.runtime.outgoing import Outgoing
from fleetlink.edge.runtime.processor import Emit, Item, Processor, Rejected, Taken
from fleetlink.edge.runtime.records import RecordMaker
from fleetlink.edge.runtime.types import TypeStoreCodecs
from fleetlink.edge.spool import MemoryBuffer, RecordBuffer, SpoolBatch, SpoolStats
from fleetlink.edge.spool.marks import decode_marks, encode_marks
from fleetlink.roswire import cdr
from fleetlink.roswire.errors import PayloadError
from fleetlink.roswire.subscriber import RosSample
from fleetlink.schemas.typestore import load_typestore
from fleetlink.wire import Record, decode_payload, encode_payload
from fleetlink.wire.groups import encode_group
from tests.helpers import wait_until

STRING = "std_msgs/msg/String"


@cache
def codecs() -> TypeStoreCodecs:
    return TypeStoreCodecs(load_typestore("jazzy"), "jazzy")


def string_sample(topic: str, text: str, seq: int) -> RosSample:
    return RosSample(
        topic=topic,
        typename=STRING,
        type_hash="RIHS01_" + "0" * 64,
        payload=cdr.encode_string(text),
        seq=seq,
        source_ts_ns=seq * 1_000_000,
        gid=None,
        key="k",
        received_ns=0,
    )


def maker() -> RecordMaker:
    table = MappingTable(
        [],
        [
            MappingSpec(name="chat", source="/{robot}/chat", topic="fleet.chat"),
            MappingSpec(name="fast", source="/{robot}/fast", topic="fleet.fast", delivery="best_effort"),
            MappingSpec(name="slow", source="/{robot}/slow", topic="fleet.slow", linger_ns=1_500_000_000),
            MappingSpec(
                name="slower", source="/{robot}/slower", topic="fleet.slower", linger_ns=3_000_000_000
            ),
            MappingSpec(name="now", source="/{robot}/now", topic="fleet.now", linger_ns=0),
        ],
    )
    return RecordMaker(site="s", edge_id="e", match=table.match, types=codecs(), dead_letter_topic="dlq")


class RefusingBuffer(MemoryBuffer):
    """Takes ``room`` records, then behaves like a spool whose ``block`` policy timed out."""

    def __init__(self, room: int) -> None:
        super().__init__(stream="durable", first_seq=1)
        self.room = room

    def append_many(self, payloads: Sequence[bytes]) -> list[int | None]:
        taken = min(self.room, len(payloads))
        self.room -= taken
        results = super().append_many(payloads[:taken])
        if taken < len(payloads):
            raise SpoolFullError("the spool is full", taken=taken)
        return results


def topics_in(buffer: RecordBuffer) -> list[tuple[str, bytes | None]]:
    batch: SpoolBatch | None = buffer.read_unacked(10_000, 1 << 30)
    if batch is None:
        return []
    records = [decode_payload(r.payload) for r in batch.records]
    return [(r.kafka_topic, r.value[-3:] if r.raw_value else r.key) for r in records]


def test_order_and_delivery_classes() -> None:
    intake: Intake[Item] = Intake()
    durable, memory = MemoryBuffer(stream="durable", first_seq=1), MemoryBuffer(first_seq=1)
    woken: list[str] = []
    processor = Processor(
        intake,
        maker(),
        {"at_least_once": durable, "best_effort": memory},
        on_appended=lambda delivery, _linger: woken.append(delivery),
    )
    event = Outgoing.of(
        "at_least_once", Record(kafka_topic="fleetlink.robots", key=b"r9", value=b"ev", raw_value=True)
    )
    items: list[Item] = [
        string_sample("/r1/chat", "a", 1),
        string_sample("/r2/fast", "b", 1),
        string_sample("/r1/chat", "c", 2),
        Emit((event,)),
        Rejected("/r1/chat", PayloadError("0/r1/chat/x/y", STRING, b"bad", "no attachment"), 5),
        string_sample("/nobody/else", "d", 1),
    ]
    for item in items:
        intake.offer(item)
    with processor:
        wait_until(lambda: processor.stats.appended == 5, 5)
    assert topics_in(durable) == [
        ("fleet.chat", b"r1"),
        ("fleet.chat", b"r1"),
        ("fleetlink.robots", b"ev"),
        ("dlq", b"bad"),
    ]
    assert topics_in(memory) == [("fleet.fast", b"r2")]
    stats = processor.counters()
    assert stats["processor"] == {
        "samples": 4,
        "records": 5,
        "appended": 5,
        "spool_dropped": 0,
        "spool_refused": 0,
        "errors": 0,
        "takes": 0,  # no data plane: everything came through the intake
    }
    assert set(woken) == {"at_least_once", "best_effort"}


@pytest.mark.parametrize(
    ("topics", "expected"),
    [
        (["/r1/slow"], 1.5),
        (["/r1/slower", "/r1/slow", "/r1/slower"], 1.5),
        (["/r1/slow", "/r1/chat"], 0.02),  # a record with no linger of its own: the edge's default
        (["/r1/chat"], 0.02),
        (["/r1/now", "/r1/chat"], 0.0),  # a mapping may also be in more of a hurry than the default
    ],
)
def test_each_append_says_how_long_its_records_may_wait(topics: list[str], expected: float) -> None:
    intake: Intake[Item] = Intake()
    durable = MemoryBuffer(stream="durable", first_seq=1)
    lingers: list[tuple[str, float]] = []
    processor = Processor(
        intake,
        maker(),
        {"at_least_once": durable, "best_effort": MemoryBuffer()},
        on_appended=lambda delivery, linger: lingers.append((delivery, linger)),
        default_linger_s=0.02,
    )
    intake.offer_many([(string_sample(topic, "x", n + 1), 1) for n, topic in enumerate(topics)])
    with processor:
        wait_until(lambda: processor.stats.appended == len(topics), 5)
    assert lingers == [("at_least_once", expected)]


def test_a_full_spool_refuses_and_counts() -> None:
    intake: Intake[Item] = Intake()
    durable = RefusingBuffer(room=3)
    processor = Processor(intake, maker(), {"at_least_once": durable, "best_effort": MemoryBuffer()})
    for i in range(5):
        intake.offer(string_sample("/r1/chat", f"m{i}", i))
    with processor:
        wait_until(lambda: processor.stats.appended + processor.stats.spool_refused == 5, 5)
    assert (processor.stats.appended, processor.stats.spool_refused) == (3, 2)
    stats: SpoolStats = durable.stats()
    assert stats.appended == 3


def test_drop_newest_results_are_counted() -> None:
    intake: Intake[Item] = Intake()
    small = MemoryBuffer(stream="durable", first_seq=1, max_records=2)
    small.read_unacked(10, 100)  # nothing yet
    processor = Processor(intake, maker(), {"at_least_once": small, "best_effort": MemoryBuffer()})
    intake.offer(string_sample("/r1/chat", "x", 1))
    intake.offer(string_sample("/r1/chat", "y", 2))
    with processor:
        wait_until(lambda: processor.stats.appended == 2, 5)
        batch = small.read_unacked(10, 1 << 20)  # both in flight: the next record cannot make room
        assert batch is not None
        intake.offer(string_sample("/r1/chat", "z", 3))
        wait_until(lambda: processor.stats.spool_dropped == 1, 5)


class CallLog(MemoryBuffer):
    """A buffer that notes the order of marks and appends."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream=stream, first_seq=1)
        self.calls: list[object] = []

    def note_marks(self, marks: bytes) -> None:
        self.calls.append(("marks", sorted(decode_marks(marks))))

    def append_groups(self, groups: Sequence[bytes]) -> int:
        self.calls.append(("groups", len(groups)))
        return super().append_groups(groups)

    def append_many(self, payloads: Sequence[bytes]) -> list[int | None]:
        self.calls.append("records")
        return super().append_many(payloads)


class OneTake:
    """A sample source that brings one ``Taken`` (the data plane's shape), then nothing."""

    def __init__(self, taken: Taken) -> None:
        self.pending: list[Taken] = [taken]

    def take(self, max_samples: int, timeout_s: float) -> Taken:
        if self.pending:
            return self.pending.pop()
        time.sleep(min(timeout_s, 0.01))  # ok-sleep: a take that waits and finds nothing
        return Taken()

    def wake(self) -> None:
        return None

    def sync(self, table_version: int) -> None:
        return None

    def install(self, maker: RecordMaker, keys: Iterable[str]) -> None:
        return None


def native_group(text: bytes) -> bytes:
    return encode_group(
        [encode_payload(Record(kafka_topic="fleet.imu", key=b"r1", value=text, raw_value=True))]
    )


G1, G2 = b"\x01" * 16, b"\x02" * 16


@pytest.mark.parametrize("general", [True, False])
def test_marks_go_to_the_spool_just_before_its_last_append_of_the_chunk(general: bool) -> None:
    sample = string_sample("/r1/chat", "a", 9)._replace(gid=G2)  # the general path
    taken = Taken(
        groups={
            "at_least_once": [native_group(b"x"), native_group(b"y")],
            "best_effort": [native_group(b"z")],
        },
        samples=[sample] if general else [],
        count=4 if general else 3,
        marks=encode_marks([(G1, 41), (G2, 9)] if general else [(G1, 41)]),  # the plane marks both paths
    )
    durable, memory = CallLog("durable"), CallLog("memory")
    processor = Processor(
        Intake(), maker(), {"at_least_once": durable, "best_effort": memory}, source=OneTake(taken)
    )
    with processor:
        wait_until(lambda: processor.stats.appended == (4 if general else 3), 5)
    if general:
        assert durable.calls == [("groups", 2), ("marks", [(G1, 41), (G2, 9)]), "records"]
    else:  # one append of both groups: the marks go with its last group
        assert durable.calls == [("marks", [(G1, 41)]), ("groups", 2)]
    assert memory.calls == [("groups", 1)]  # best-effort records are not what the marks describe


def test_marks_of_a_chunk_with_nothing_durable_wait_for_the_next_append() -> None:
    taken = Taken(groups={"best_effort": [native_group(b"z")]}, count=1, marks=encode_marks([(G1, 5)]))
    durable, memory = CallLog("durable"), CallLog("memory")
    processor = Processor(
        Intake(), maker(), {"at_least_once": durable, "best_effort": memory}, source=OneTake(taken)
    )
    with processor:
        wait_until(lambda: processor.stats.appended == 1, 5)
    assert durable.calls == [("marks", [(G1, 5)])]


class HoldingUploader:
    """Keeps every claim job waiting, as an object store that is down does."""

    def __init__(self) -> None:
        self.jobs: list[ClaimJob] = []

    def submit(self, job: ClaimJob) -> Claimed | None:
        self.jobs.append(job)
        return None


def test_a_record_waiting_for_its_upload_holds_back_its_publishers_mark() -> None:
    """A crash loses a record still waiting for its object: the spool's mark must not claim it,
    so that the restart counts it in ``lost_at_restart``."""
    from tests.unit.edge.runtime.camera import image_cdr, image_sample
    from tests.unit.edge.runtime.test_records import maker_for
    from tests.unit.edge.runtime.test_records_claims import camera

    made, _, _ = maker_for([camera(above=0)])
    durable, memory = CallLog("durable"), CallLog("memory")
    uploader = HoldingUploader()
    intake: Intake[Item] = Intake()
    processor = Processor(intake, made, {"at_least_once": durable, "best_effort": memory}, uploader=uploader)
    payload = image_cdr(32, 24)
    with processor:
        for seq in (3, 4):
            intake.offer(image_sample("/cam_1/image_raw", payload, seq=seq)._replace(gid=G1))
        wait_until(lambda: len(uploader.jobs) == 2, 5)
        wait_until(lambda: ("marks", [(G1, 2)]) in durable.calls, 5)  # not 3, not 4: both wait
        processor.post(Claimed(uploader.jobs[0], error="refused"))
        wait_until(lambda: ("marks", [(G1, 3)]) in durable.calls, 5)  # 3's dead letter is spooled
        processor.post(Claimed(uploader.jobs[1], error="refused"))
        wait_until(lambda: ("marks", [(G1, 4)]) in durable.calls, 5)
    assert all(m[1][0][1] <= 4 for m in durable.calls if isinstance(m, tuple))


def test_a_group_above_the_buffer_limit_is_refused_alone_and_counted() -> None:
    small, huge = native_group(b"s"), native_group(b"h" * 4096)
    taken = Taken(groups={"at_least_once": [small, huge, native_group(b"t")]}, count=3)
    durable = MemoryBuffer(stream="durable", first_seq=1, max_bytes=1024)
    processor = Processor(Intake(), maker(), {"at_least_once": durable}, source=OneTake(taken))
    with processor:
        wait_until(lambda: processor.stats.appended + processor.stats.spool_refused == 3, 5)
    assert (processor.stats.records, processor.stats.appended, processor.stats.spool_refused) == (3, 2, 1)
    batch = durable.read_unacked(10, 1 << 20)
    assert batch is not None
    assert [g.records for g in batch.groups] == [1, 1]
    assert processor.stats.errors == 0


def early_processor(hold_s: float) -> tuple[Processor, MappingTable, CallLog, Intake[Item], RecordMaker]:
    """A processor over a table whose robot type ``tb4`` maps ``/{robot}/chat``, no robot registered."""
    table = MappingTable(
        [
            RobotTypeSpec(
                name="tb4",
                match="/tb4_*",
                mappings=(MappingSpec(name="chat", source="/{robot}/chat", topic="fleet.chat"),),
            )
        ]
    )
    made = RecordMaker(
        site="s",
        edge_id="e",
        match=table.match,
        types=codecs(),
        dead_letter_topic="dlq",
        awaits_robot=table.awaits_robot,
    )
    durable = CallLog("durable")
    intake: Intake[Item] = Intake()
    processor = Processor(
        intake,
        made,
        {"at_least_once": durable, "best_effort": CallLog("memory")},
        table_version=lambda: table.version,
        early=EarlySamples(int(hold_s * 1e9), max_samples=100, max_bytes=1 << 20),
    )
    return processor, table, durable, intake, made


def early_counts(processor: Processor) -> dict[str, int]:
    counts = processor.counters()["early"]
    assert isinstance(counts, dict)
    return counts


def test_samples_before_their_robots_registration_wait_for_it_in_order() -> None:
    processor, table, durable, intake, made = early_processor(hold_s=30)
    with processor:
        for seq, text in enumerate(("a", "b", "c"), start=1):
            intake.offer(string_sample("/tb4_01/chat", text, seq)._replace(gid=G1))
        wait_until(lambda: processor.stats.samples == 3, 5)
        wait_until(lambda: early_counts(processor)["waiting"] == 3, 5)
        assert durable.calls == [("marks", [(G1, 0)])]  # no record, and no mark past those that wait
        table.add_robot("tb4_01")
        wait_until(lambda: processor.stats.appended == 3, 5)
        intake.offer(string_sample("/tb4_01/chat", "d", 4)._replace(gid=G1))
        wait_until(lambda: processor.stats.appended == 4, 5)
    batch = durable.read_unacked(100, 1 << 20)
    assert batch is not None
    assert [decode_payload(r.payload).value[-1:] for r in batch.records] == [b"a", b"b", b"c", b"d"]
    assert ("marks", [(G1, 3)]) in durable.calls
    assert made.unmapped == {}
    early = early_counts(processor)
    assert (early["held"], early["released"], early["expired"], early["waiting"]) == (3, 3, 0, 0)


def test_samples_whose_robot_never_registers_are_given_up_and_counted_unmapped() -> None:
    processor, _table, durable, intake, made = early_processor(hold_s=0.3)
    with processor:
        for seq in (1, 2):
            intake.offer(string_sample("/tb4_01/chat", "x", seq)._replace(gid=G1))
        wait_until(lambda: made.unmapped.get("/tb4_01/chat") == 2, 5)
        intake.offer(string_sample("/tb4_01/chat", "y", 3)._replace(gid=G1))  # the topic was given up
        wait_until(lambda: made.unmapped.get("/tb4_01/chat") == 3, 5)
        wait_until(lambda: ("marks", [(G1, 3)]) in durable.calls, 5)  # counted: the marks move on
    assert processor.stats.appended == 0
    plan = made.plan_for("k")  # the data key the samples came on: dropped natively from now on
    assert plan is not None
    assert plan.lanes == ()
    early = early_counts(processor)
    assert (early["held"], early["released"], early["expired"], early["waiting"]) == (2, 0, 2, 0)
