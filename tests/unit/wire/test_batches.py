"""The edge <-> uplink wire contract: round trips, exact failures, fuzzing, key expressions."""

from __future__ import annotations

import contextlib
import dataclasses
import struct
import zlib
from typing import Literal

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fleetlink.wire import (
    BATCH_VERSION,
    FLAG_SOURCE_SEQ,
    SOURCE_SEQ_HEADER,
    Ack,
    Batch,
    Codec,
    PayloadTemplate,
    Record,
    RecordFailure,
    WireError,
    ack_key,
    admin_key,
    command_key,
    decode_ack,
    decode_batch,
    decode_batch_head,
    decode_payload,
    encode_ack,
    encode_batch,
    encode_batch_payloads,
    encode_payload,
    events_key,
    ingest_key,
    payload_fingerprint,
    payload_fingerprints,
    single_object,
    site_prefix,
    split_single_object,
    zstd_available,
)
from fleetlink.wire.batch import PEEK_BYTES, StreamHead, peek_stream

FP = bytes.fromhex("0102030405060708")
FP2 = bytes.fromhex("a1a2a3a4a5a6a7a8")
SCHEMA = '{"type":"record","name":"Imu","fields":[{"name":"x","type":"double"}]}'
CODECS: list[Codec] = ["none", "zlib", "zstd"]


def rec(seq: int, **kw: object) -> Record:
    base: dict[str, object] = {
        "kafka_topic": "fleet.imu",
        "key": b"tb4_01",
        "value": single_object(FP, b"\x00" * 8),
        "headers": (("ros.topic", b"/tb4_01/imu"), ("site", b"warehouse-a")),
        "timestamp_ms": 1_700_000_000_123,
        "seq": seq,
    }
    base.update(kw)
    return Record(**base)  # type: ignore[arg-type]


def batch(records: tuple[Record, ...], **kw: object) -> Batch:
    return Batch(
        site="warehouse-a",
        edge_id="edge-1",
        stream="durable",
        first_seq=records[0].seq,
        records=records,
        schemas=kw.get("schemas", {FP: SCHEMA}),  # type: ignore[arg-type]
    )


def test_zstd_is_available_here() -> None:
    # rosbags depends on backports.zstd, so the fast codec is always there in this project
    assert zstd_available()


RECORDS: list[Record] = [
    rec(1),
    rec(2, key=None),
    rec(3, key=b""),
    rec(4, headers=()),
    rec(5, value=b"not avro at all", raw_value=True, kafka_topic="fleet.dead-letter"),
    rec(6, timestamp_ms=-1),
    rec(7, kafka_topic="ü" * 10, headers=(("ñ", b"\x00\xff"),)),
    rec(2**64 - 1, value=single_object(FP2, b"")),
]


@pytest.mark.parametrize("record", RECORDS)
def test_payload_round_trip(record: Record) -> None:
    payload = encode_payload(record)
    assert decode_payload(payload, record.seq) == record
    assert payload_fingerprint(payload) == record.fingerprint


@pytest.mark.parametrize("codec", CODECS)
def test_batch_round_trip_every_codec(codec: Codec) -> None:
    records = tuple(r for r in RECORDS if r.seq < 2**63)
    original = Batch(
        site="s", edge_id="e", stream="durable", first_seq=1, records=records, schemas={FP: SCHEMA, FP2: "{}"}
    )
    data = encode_batch(original, codec=codec)
    assert data[:3] == b"FLB"
    assert data[4] == {"none": 0, "zlib": 1, "zstd": 2}[codec]
    decoded = decode_batch(data)
    assert decoded == original
    assert decoded.last_seq == 7


def test_payload_fast_path_matches_record_encoding() -> None:
    records = (rec(10), rec(11), rec(15))
    slow = encode_batch(batch(records))
    fast = encode_batch_payloads(
        site="warehouse-a",
        edge_id="edge-1",
        stream="durable",
        items=[(r.seq, encode_payload(r)) for r in records],
        schemas={FP: SCHEMA},
    )
    assert slow == fast


TEMPLATED: list[tuple[Record, int | None]] = [
    (rec(1), 42),
    (rec(2), None),
    (rec(3, key=None), 0),
    (rec(4, key=b"", headers=()), 2**64 - 1),
    (rec(5, kafka_topic="ü" * 10, headers=(("ñ", b"\x00\xff"),)), 7),
    (rec(6, timestamp_ms=-1, value=b""), 1),
]


@pytest.mark.parametrize(("record", "source_seq"), TEMPLATED)
def test_template_payload_is_the_record_with_its_seq_header(record: Record, source_seq: int | None) -> None:
    template = PayloadTemplate(record.kafka_topic, record.key, record.headers)
    payload = template.payload(record.value, record.timestamp_ms, source_seq)
    if source_seq is None:
        assert payload == encode_payload(record)
        expected = record
    else:
        assert payload[0] & FLAG_SOURCE_SEQ
        expected = record._replace(headers=(*record.headers, (SOURCE_SEQ_HEADER, str(source_seq).encode())))
    assert decode_payload(payload, record.seq) == expected
    assert payload_fingerprint(payload) == record.fingerprint
    data = encode_batch_payloads(site="s", edge_id="e", stream="d", items=[(record.seq, payload)], schemas={})
    assert decode_batch(data).records == (expected,)


@pytest.mark.parametrize("source_seq", [-1, 2**64])
def test_template_refuses_a_source_seq_beyond_u64(source_seq: int) -> None:
    with pytest.raises(WireError, match="does not fit a u64"):
        PayloadTemplate("t", b"k").payload(b"v", 0, source_seq)


def test_version_5_is_the_only_one_written_and_read() -> None:
    record = rec(1)
    assert encode_batch(batch((record,)))[3] == BATCH_VERSION == 6
    assert decode_batch(_raw(_body([(1, encode_payload(record))]))).records == (record,)
    for version in (1, 2, 3, 4):
        with pytest.raises(WireError, match=f"unsupported batch version {version}"):
            decode_batch(_raw(_body([(1, encode_payload(record))]), version=version))
    seq_payload = PayloadTemplate("t", b"k").payload(b"v", 0, 5)
    assert decode_batch(_raw(_body([(1, seq_payload)]))).records[0].headers == ((SOURCE_SEQ_HEADER, b"5"),)


def test_the_origin_of_an_exactly_once_stream_travels_in_the_head() -> None:
    sent = batch((rec(7), rec(8)))
    assert decode_batch(encode_batch(sent)).origin == 0
    eo = decode_batch(encode_batch(dataclasses.replace(sent, origin=2**64 - 1)))
    assert (eo.origin, eo.records) == (2**64 - 1, sent.records)
    assert decode_batch_head(encode_batch(dataclasses.replace(sent, origin=42))).head.origin == 42
    with pytest.raises(WireError, match="does not fit a u64"):
        encode_batch(dataclasses.replace(sent, origin=2**64))


def test_the_edges_ack_mark_travels_in_the_head_below_the_first_seq() -> None:
    sent = batch((rec(7), rec(8)))
    assert decode_batch(encode_batch(sent)).acked == 0
    assert decode_batch_head(encode_batch(dataclasses.replace(sent, acked=6))).head.acked == 6
    with pytest.raises(WireError, match="acked 7 must be below the first seq 7"):
        encode_batch(dataclasses.replace(sent, acked=7))
    forged = _raw(_body([(7, GOOD)]).replace(struct.pack("<QQQ", 0, 7, 0), struct.pack("<QQQ", 0, 7, 9)))
    with pytest.raises(WireError, match="acked 9 must be below the first seq 7"):
        decode_batch(forged)


def test_records_sharing_a_tail_keep_their_own_key_value_and_seq() -> None:
    # key=None and key=b"" have the same tail bytes; only the null-key flag tells them apart
    template = PayloadTemplate("fleet.imu", b"", (("a", b"1"),))
    null_key = encode_payload(rec(2, key=None, headers=(("a", b"1"),)))
    items = [(1, template.payload(b"x", 1, 10)), (2, null_key), (3, template.payload(b"yy", 3, 11))]
    got = decode_batch(encode_batch_payloads(site="s", edge_id="e", stream="d", items=items, schemas={}))
    assert [(r.key, r.value, r.headers[-1]) for r in got.records] == [
        (b"", b"x", (SOURCE_SEQ_HEADER, b"10")),
        (None, rec(2).value, ("a", b"1")),
        (b"", b"yy", (SOURCE_SEQ_HEADER, b"11")),
    ]


def test_compression_pays_on_repetitive_records() -> None:
    records = tuple(rec(i) for i in range(1, 501))
    none = len(encode_batch(batch(records), codec="none"))
    assert len(encode_batch(batch(records), codec="zlib")) < none / 5
    assert len(encode_batch(batch(records), codec="zstd")) < none / 5


def test_single_object_helpers() -> None:
    value = single_object(FP, b"body")
    fingerprint, body = split_single_object(value)
    assert (fingerprint, bytes(body)) == (FP, b"body")
    with pytest.raises(WireError, match="not an Avro single-object"):
        split_single_object(b"\x00\x00" + FP)
    with pytest.raises(WireError, match="8 bytes"):
        single_object(b"short", b"")
    assert rec(1, value=b"\xc3\x01short").fingerprint is None


def _raw(
    body: bytes, *, codec: int = 0, size: int | None = None, magic: bytes = b"FLB", version: int = 6
) -> bytes:
    header = struct.pack("<3sBBI", magic, version, codec, len(body) if size is None else size)
    return header + (zlib.compress(body) if codec == 1 else body)


def _body(records: list[tuple[int, bytes]], first_seq: int | None = None, trailing: bytes = b"") -> bytes:
    first = records[0][0] if first_seq is None else first_seq
    out = b"\x01\x00s\x01\x00e\x01\x00d" + struct.pack("<QQQH", 0, first, 0, 0)
    out += struct.pack("<I", len(records))
    for seq, payload in records:  # each record a group of its own
        group = struct.pack("<IHI", 1, 0, len(payload)) + payload
        out += struct.pack("<QI", seq, len(group)) + group
    return out + trailing


GOOD = encode_payload(rec(1))

BAD_BATCHES: list[tuple[bytes, str]] = [
    (b"", "at least 9 bytes"),
    (b"FLB\x01\x00", "at least 9 bytes"),
    (_raw(_body([(1, GOOD)]), magic=b"XYZ"), "not a fleetlink batch"),
    (_raw(_body([(1, GOOD)]), version=3), "unsupported batch version 3"),
    (_raw(_body([(1, GOOD)]), version=0), "unsupported batch version 0"),
    (_raw(_body([(1, GOOD)]), codec=7), "unknown codec 7"),
    (_raw(_body([(1, GOOD)]), size=10), "header says 10"),
    (_raw(_body([(1, GOOD)]), size=2**31), "exceeds the"),
    (_raw(b"garbage", codec=1, size=7)[:-3] + b"zzz", "corrupt zlib data"),
    (_raw(_body([(1, GOOD)], trailing=b"x")), "1 unexpected trailing bytes after the batch"),
    (_raw(_body([(2, GOOD), (2, GOOD)])), "seqs must increase: a group starts at 2, below 3"),
    (_raw(_body([(1, GOOD)], first_seq=0)), "first_seq 0 is not the first record's seq 1"),
    (_raw(b"\x01\x00s\x01\x00e\x01\x00d" + struct.pack("<QQQHI", 0, 1, 0, 0, 0)), "at least one record"),
    (_raw(_body([(1, GOOD[:-1])])), "truncated"),
    (_raw(_body([(1, GOOD + b"!")])), "trailing bytes after the record"),
    (_raw(_body([(1, b"\x80" + GOOD[1:])])), "unknown record flags 0x80"),
    (_raw(b"\x02\x00\xff\xfe"), "site is not valid UTF-8"),
]


@pytest.mark.parametrize(("data", "reason"), BAD_BATCHES)
def test_bad_batches_raise_wire_error_with_reason(data: bytes, reason: str) -> None:
    with pytest.raises(WireError) as info:
        decode_batch(data)
    assert reason in str(info.value)


def test_decompression_bomb_is_refused_before_inflating() -> None:
    body = _body([(1, encode_payload(rec(1, value=b"\x00" * 2_000_000, raw_value=True)))])
    data = _raw(body, codec=1)
    assert len(data) < 10_000
    with pytest.raises(WireError, match="exceeds the 1000000-byte limit"):
        decode_batch(data, max_bytes=1_000_000)
    assert decode_batch(data).records[0].value == b"\x00" * 2_000_000


def test_encoder_refuses_what_the_decoder_would_refuse() -> None:
    with pytest.raises(WireError, match="at least one record"):
        encode_batch_payloads(site="s", edge_id="e", stream="d", items=[], schemas={})
    with pytest.raises(WireError, match="must increase"):
        encode_batch(batch((rec(3), rec(2))))
    with pytest.raises(WireError, match="first_seq"):
        encode_batch(Batch(site="s", edge_id="e", stream="d", first_seq=1, records=(rec(2),)))
    with pytest.raises(WireError, match="8 bytes"):
        encode_batch(batch((rec(1),), schemas={b"x": "{}"}))
    with pytest.raises(WireError, match="16-bit"):
        encode_payload(rec(1, kafka_topic="x" * 70_000))


ACKS: list[Ack] = [
    Ack(edge_id="edge-1", stream="durable", first_seq=1, last_seq=500, status="ok"),
    Ack(edge_id="edge-1", stream="durable", first_seq=1, last_seq=5, status="ok", max_record_bytes=1_000_000),
    Ack(
        edge_id="edge-1",
        stream="durable",
        first_seq=1,
        last_seq=1,
        status="ok",
        failures=(RecordFailure(seq=1, reason="message too large: 2 MB", dead_lettered=True),),
    ),
    Ack(
        edge_id="e",
        stream="memory",
        first_seq=7,
        last_seq=9,
        status="error",
        detail="Kafka unavailable",
        failures=(RecordFailure(seq=8, reason="timed out", dead_lettered=False),),
    ),
    Ack(
        edge_id="e",
        stream="durable",
        first_seq=3,
        last_seq=4,
        status="need_schemas",
        missing_schemas=(FP, FP2),
        detail="send the batch again with these schemas",
    ),
    Ack(
        edge_id="e",
        stream="durable",
        first_seq=11,
        last_seq=20,
        status="held_back",
        detail="batch 1.. of this stream was not produced: it goes first",
    ),
]


def test_a_batch_lists_left_out_schemas_by_fingerprint_alone() -> None:
    schema = '{"type": "record", "name": "Imu", "fields": []}' * 20
    records = (rec(1), rec(2))
    full = batch(records, schemas={FP: schema})
    lean = Batch(
        site=full.site,
        edge_id=full.edge_id,
        stream=full.stream,
        first_seq=1,
        records=records,
        elided=frozenset({FP}),
    )
    decoded = decode_batch(encode_batch(lean, codec="none"))
    assert (decoded.schemas, decoded.elided) == ({}, frozenset({FP}))
    assert len(encode_batch(full, codec="none")) - len(encode_batch(lean, codec="none")) == len(schema)
    with pytest.raises(WireError, match="both carried and elided"):
        encode_batch(
            Batch(
                site="s",
                edge_id="e",
                stream="d",
                first_seq=1,
                records=records,
                schemas={FP: schema},
                elided=frozenset({FP}),
            )
        )

    def body(entries: int) -> bytes:
        head = b"\x01\x00s\x01\x00e\x01\x00d" + struct.pack("<QQQH", 0, 1, 0, entries)
        return head + (FP + b"\xff\xff\xff\xff") * entries + _body([(1, encode_payload(rec(1)))])[35:]

    assert decode_batch(_raw(body(1))).elided == frozenset({FP})
    with pytest.raises(WireError, match="listed twice"):
        decode_batch(_raw(body(2)))


@pytest.mark.parametrize("ack", ACKS)
def test_ack_round_trip(ack: Ack) -> None:
    assert decode_ack(encode_ack(ack)) == ack


def test_ack_invariants() -> None:
    with pytest.raises(WireError, match="only dead-lettered"):
        Ack(
            edge_id="e",
            stream="d",
            first_seq=1,
            last_seq=2,
            status="ok",
            failures=(RecordFailure(seq=1, reason="x", dead_lettered=False),),
        )
    with pytest.raises(WireError, match="empty"):
        Ack(edge_id="e", stream="d", first_seq=3, last_seq=2, status="ok")
    with pytest.raises(WireError, match="missing schemas"):
        Ack(edge_id="e", stream="d", first_seq=1, last_seq=2, status="need_schemas")
    with pytest.raises(WireError, match="missing schemas"):
        Ack(edge_id="e", stream="d", first_seq=1, last_seq=2, status="ok", missing_schemas=(FP,))
    with pytest.raises(WireError, match="8 bytes"):
        Ack(edge_id="e", stream="d", first_seq=1, last_seq=2, status="need_schemas", missing_schemas=(b"x",))
    with pytest.raises(WireError, match="max_record_bytes"):
        Ack(edge_id="e", stream="d", first_seq=1, last_seq=2, status="ok", max_record_bytes=-1)
    said = encode_ack(ACKS[1])
    assert said[-4:] == (1_000_000).to_bytes(4, "little")  # the limit ends the ack
    assert decode_ack(said).max_record_bytes == 1_000_000
    assert decode_ack(said[:-4]).max_record_bytes == 0  # an uplink from before the limit was told
    good = encode_ack(ACKS[0])
    with pytest.raises(WireError, match="not a fleetlink ack"):
        decode_ack(b"XXX" + good[3:])
    with pytest.raises(WireError, match="unsupported ack version 9"):
        decode_ack(good[:3] + b"\x09" + good[4:])
    with pytest.raises(WireError, match="trailing"):
        decode_ack(good + b"\x00")
    with pytest.raises(WireError, match="truncated"):
        decode_ack(good[:-1])


KEYS: list[tuple[str, str]] = [
    (site_prefix("warehouse-a"), "fleetlink/warehouse-a"),
    (ingest_key("warehouse-a", "edge-1"), "fleetlink/warehouse-a/ingest/edge-1"),
    (ack_key("warehouse-a", "edge-1"), "fleetlink/warehouse-a/ack/edge-1"),
    (command_key("warehouse-a", "tb4_01", "lightring"), "fleetlink/warehouse-a/command/tb4_01/lightring"),
    (command_key("w", "fleet/tb4_01", "dock"), "fleetlink/w/command/fleet/tb4_01/dock"),
    (events_key("warehouse-a"), "fleetlink/warehouse-a/events"),
    (admin_key("warehouse-a"), "fleetlink/warehouse-a/admin/**"),
]


@pytest.mark.parametrize(("key", "expected"), KEYS)
def test_keys_live_under_the_site_prefix(key: str, expected: str) -> None:
    assert key == expected


@pytest.mark.parametrize(
    "call",
    [
        lambda: site_prefix("a/b"),
        lambda: site_prefix("*"),
        lambda: site_prefix(""),
        lambda: ingest_key("s", "e/1"),
        lambda: ingest_key("s", "$e"),
        lambda: command_key("s", "r//x", "c"),
        lambda: command_key("s", "r", "a/b"),
        lambda: events_key("s p"),
        lambda: ack_key("s", "**"),
    ],
)
def test_names_that_would_escape_the_site_are_refused(call: object) -> None:
    with pytest.raises(WireError):
        call()  # type: ignore[operator]


# --- property-based -----------------------------------------------------------------------------
texts = st.text(max_size=20)
records_st = st.builds(
    Record,
    kafka_topic=texts,
    key=st.none() | st.binary(max_size=30),
    value=st.binary(max_size=60) | st.binary(max_size=40).map(lambda b: single_object(FP, b)),
    headers=st.lists(st.tuples(texts, st.binary(max_size=20)), max_size=4).map(tuple),
    timestamp_ms=st.integers(-(2**63), 2**63 - 1),
    raw_value=st.booleans(),
)


@st.composite
def batches(draw: st.DrawFn) -> Batch:
    rs = draw(st.lists(records_st, min_size=1, max_size=8))
    seqs = sorted(draw(st.sets(st.integers(0, 2**64 - 1), min_size=len(rs), max_size=len(rs))))
    records = tuple(
        Record(r.kafka_topic, r.key, r.value, r.headers, r.timestamp_ms, s, r.raw_value)
        for r, s in zip(rs, seqs, strict=True)
    )
    schemas = draw(st.dictionaries(st.binary(min_size=8, max_size=8), texts, max_size=3))
    elided = draw(
        st.frozensets(st.binary(min_size=8, max_size=8).filter(lambda fp: fp not in schemas), max_size=3)
    )
    return Batch(
        site=draw(texts),
        edge_id=draw(texts),
        stream=draw(texts),
        first_seq=seqs[0],
        records=records,
        schemas=schemas,
        elided=elided,
    )


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
@given(batches(), st.sampled_from(CODECS))
def test_any_batch_round_trips(original: Batch, codec: Codec) -> None:
    assert decode_batch(encode_batch(original, codec=codec)) == original


@settings(max_examples=500)
@given(st.binary(max_size=300))
def test_garbage_raises_only_wire_error(data: bytes) -> None:
    for decode in (decode_batch, decode_ack, decode_payload):
        with contextlib.suppress(WireError):
            decode(data)


@settings(max_examples=500, suppress_health_check=[HealthCheck.too_slow])
@given(batches(), st.data())
def test_mutated_batches_decode_or_raise_wire_error(original: Batch, data: st.DataObject) -> None:
    encoded = bytearray(encode_batch(original, codec=data.draw(st.sampled_from(CODECS))))
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(encoded) - 1))
        encoded[i] = data.draw(st.integers(0, 255))
    cut = data.draw(st.integers(0, len(encoded)))
    try:
        decoded = decode_batch(bytes(encoded[:cut]) if data.draw(st.booleans()) else bytes(encoded))
    except WireError:
        return
    assert len(decoded.records) >= 1


@settings(max_examples=300)
@given(
    st.lists(
        st.builds(RecordFailure, seq=st.integers(0, 2**64 - 1), reason=texts, dead_lettered=st.booleans()),
        max_size=5,
    ),
    st.integers(0, 2**63),
    st.integers(0, 2**63),
    texts,
)
def test_any_ack_round_trips(failures: list[RecordFailure], a: int, n: int, detail: str) -> None:
    status: Literal["ok", "error"] = "ok" if all(f.dead_lettered for f in failures) else "error"
    if a + n >= 2**64:  # a sequence number is a u64: such a range is refused, not wrapped
        with pytest.raises(WireError, match="not within"):
            Ack(edge_id="e", stream="s", first_seq=a, last_seq=a + n, status=status)
        return
    ack = Ack(
        edge_id="e",
        stream="s",
        first_seq=a,
        last_seq=a + n,
        status=status,
        failures=tuple(failures),
        detail=detail,
    )
    assert decode_ack(encode_ack(ack)) == ack


@settings(max_examples=200, suppress_health_check=[HealthCheck.too_slow])
@given(batches(), st.lists(st.none() | st.integers(0, 2**64 - 1), min_size=8, max_size=8), st.data())
def test_templated_batches_round_trip_or_raise_wire_error_when_mutated(
    original: Batch, source_seqs: list[int | None], data: st.DataObject
) -> None:
    items = []
    expected = []
    for record, source_seq in zip(original.records, source_seqs, strict=False):
        if record.raw_value:
            items.append((record.seq, encode_payload(record)))
            expected.append(record)
            continue
        template = PayloadTemplate(record.kafka_topic, record.key, record.headers)
        items.append((record.seq, template.payload(record.value, record.timestamp_ms, source_seq)))
        extra = () if source_seq is None else ((SOURCE_SEQ_HEADER, str(source_seq).encode()),)
        expected.append(record._replace(headers=record.headers + extra))
    codec = data.draw(st.sampled_from(CODECS))
    encoded = encode_batch_payloads(
        site=original.site,
        edge_id=original.edge_id,
        stream=original.stream,
        items=items,
        schemas=original.schemas,
        codec=codec,
    )
    assert decode_batch(encoded).records == tuple(expected)
    mutated = bytearray(encoded)
    i = data.draw(st.integers(0, len(mutated) - 1))
    mutated[i] = data.draw(st.integers(0, 255))
    with contextlib.suppress(WireError):
        assert len(decode_batch(bytes(mutated)).records) >= 1


@settings(max_examples=200)
@given(st.lists(records_st, max_size=6), st.lists(st.binary(max_size=30), max_size=3))
def test_payload_fingerprints_is_the_set_of_each_payload_fingerprint(
    records: list[Record], junk: list[bytes]
) -> None:
    payloads = [encode_payload(r) for r in records] + junk
    expected = {fp for p in payloads if (fp := payload_fingerprint(p)) is not None}
    assert payload_fingerprints(payloads) == expected


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
@given(batches(), st.sampled_from(CODECS), st.integers(0, 2**64 - 1))
def test_peek_reads_a_batchs_stream_from_its_start(original: Batch, codec: Codec, origin: int) -> None:
    original = dataclasses.replace(original, origin=origin)
    head = peek_stream(encode_batch(original, codec=codec))
    names = sum(len(t.encode()) + 2 for t in (original.site, original.edge_id, original.stream))
    expected = StreamHead(original.site, original.edge_id, original.stream, origin, original.first_seq)
    assert head == (expected if names + 24 <= PEEK_BYTES else None)


@pytest.mark.parametrize("codec", CODECS)
def test_peek_stops_at_the_head_of_a_large_batch(codec: Codec) -> None:
    records = tuple(rec(seq, value=single_object(FP, bytes(range(256)) * 8)) for seq in range(5, 2005))
    data = encode_batch(batch(records), codec=codec)
    assert peek_stream(data) == StreamHead("warehouse-a", "edge-1", "durable", 0, 5)
    assert peek_stream(data[:40]) in (None, StreamHead("warehouse-a", "edge-1", "durable", 0, 5))
    assert peek_stream(b"FLX" + data[3:]) is None  # not a batch


@settings(max_examples=500)
@given(st.binary(max_size=300))
def test_peek_at_garbage_says_none_or_a_head(data: bytes) -> None:
    assert peek_stream(data) is None or isinstance(peek_stream(data), StreamHead)


def test_peek_says_none_for_what_the_head_decoder_refuses() -> None:
    data = encode_batch(batch((rec(5),)), codec="none")
    assert peek_stream(data) == StreamHead("warehouse-a", "edge-1", "durable", 0, 5)
    assert peek_stream(data, max_bytes=10) is None  # a body above the limit
    acked_at = 9 + sum(2 + len(t) for t in (b"warehouse-a", b"edge-1", b"durable")) + 16
    bad = data[:acked_at] + struct.pack("<Q", 5) + data[acked_at + 8 :]  # acked not below first seq
    with pytest.raises(WireError, match="acked 5 must be below"):
        decode_batch(bad)
    assert peek_stream(bad) is None
