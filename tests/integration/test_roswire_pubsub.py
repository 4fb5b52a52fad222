"""Publishing and subscribing as rmw_zenoh does, checked on the wire with raw zenoh sessions."""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Iterator

import pytest
import zenoh
from rosbags.typesys.store import Typestore

from fleetlink.roswire.attachment import decode, encode
from fleetlink.roswire.errors import AttachmentError, KeyParseError, PayloadError, RoswireError
from fleetlink.roswire.gid import entity_gid
from fleetlink.roswire.names import data_key
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.qos import SENSOR_DATA, TRANSIENT_LOCAL
from fleetlink.roswire.subscriber import RosSample, RosSubscriber
from fleetlink.roswire.tokens import EndpointInfo, parse_token
from fleetlink.roswire.wire_detect import probe_wire
from fleetlink.schemas.typestore import load_typestore
from tests.helpers import wait_until, zenoh_peer_config

STRING = "std_msgs/msg/String"
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
_domains = itertools.count(201)


@pytest.fixture(scope="module")
def typestore() -> Typestore:
    return load_typestore("jazzy")


@pytest.fixture
def domain() -> int:
    return next(_domains)


@pytest.fixture
def raw(zenoh_router: str) -> Iterator[zenoh.Session]:
    with zenoh.open(zenoh_peer_config(zenoh_router)) as session:
        yield session


@pytest.fixture
def node(zenoh_router: str, domain: int, typestore: Typestore) -> Iterator[RosNode]:
    with RosNode(
        "talker", "/tb4_01", domain_id=domain, config=zenoh_peer_config(zenoh_router), typestore=typestore
    ) as n:
        yield n


def test_publisher_puts_exact_key_cdr_and_attachment(
    node: RosNode, raw: zenoh.Session, domain: int, typestore: Typestore
) -> None:
    got: list[tuple[str, bytes, bytes | None]] = []
    tokens: list[str] = []
    raw.declare_subscriber(
        f"{domain}/**",
        lambda s: got.append(
            (str(s.key_expr), s.payload.to_bytes(), s.attachment.to_bytes() if s.attachment else None)
        ),
    )
    raw.liveliness().declare_subscriber(
        f"@ros2_lv/{domain}/**", lambda s: tokens.append(str(s.key_expr)), history=True
    )
    pub = node.create_publisher("chatter", STRING)
    wait_until(lambda: pub.matching, timeout=5, message="raw subscriber matched")
    before = time.time_ns()
    for i in range(3):
        assert pub.publish(typestore.types[STRING](data=f"hello {i}")) == i + 1
    wait_until(lambda: len(got) == 3, timeout=5, message="3 samples on the wire")
    after = time.time_ns()
    key = f"{domain}/tb4_01/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    assert [k for k, _, _ in got] == [key] * 3
    assert got[0][1] == bytes.fromhex("000100000800000068656c6c6f203000")
    atts = [decode(a or b"") for _, _, a in got]
    assert [a.seq for a in atts] == [1, 2, 3]
    assert all(len(a or b"") == 33 for _, _, a in got)
    assert all(before <= a.source_ts_ns <= after for a in atts)
    expected_token = (
        f"@ros2_lv/{domain}/{node.zid}/{node.nid}/{pub.eid}/MP/%/%tb4_01/talker/"
        f"%tb4_01%chatter/std_msgs::msg::dds_::String_/{STRING_HASH}/::,10:,:,:,,"
    )
    wait_until(lambda: expected_token in tokens, timeout=5, message="MP token with honest QoS")
    assert f"@ros2_lv/{domain}/{node.zid}/{node.nid}/{node.nid}/NN/%/%tb4_01/talker" in tokens
    assert {a.gid for a in atts} == {entity_gid(expected_token)}
    assert pub.token_key == expected_token


def test_v1_publisher_and_both_versions_received(node: RosNode, domain: int) -> None:
    samples: list[RosSample] = []
    sub = node.create_subscriber("/mixed", STRING, samples.append, type_hash=STRING_HASH)
    v2 = node.create_publisher("/mixed", STRING, type_hash=STRING_HASH)
    v1 = node.create_publisher("/mixed", STRING, type_hash=STRING_HASH, attachment_version=1)
    wait_until(lambda: v1.matching and v2.matching, timeout=5, message="publishers matched")
    v2.publish_cdr(b"\x00\x01\x00\x00\x02\x00\x00\x00a\x00")
    v1.publish_cdr(b"\x00\x01\x00\x00\x02\x00\x00\x00b\x00")
    wait_until(lambda: len(samples) == 2, timeout=5, message="both samples delivered")
    by_version = {s.attachment_version: s for s in samples}
    assert by_version[2].gid == v2.gid
    assert by_version[1].gid == v1.gid
    assert {s.seq for s in samples} == {1}
    assert sub.stats.attachment_versions == {1: 1, 2: 1}
    assert sub.stats.rejected == 0
    assert samples[0].topic == "/mixed"
    assert samples[0].typename == STRING


def test_sequence_gaps_and_duplicates_counted_per_publisher(
    node: RosNode, raw: zenoh.Session, domain: int
) -> None:
    samples: list[RosSample] = []
    sub = node.create_subscriber("/gappy", STRING, samples.append, type_hash=STRING_HASH)
    key = data_key(domain, "/gappy", STRING, STRING_HASH)
    pub = raw.declare_publisher(key)
    wait_until(lambda: pub.matching_status.matching, timeout=5, message="subscriber matched")  # type: ignore[attr-defined]
    payload = b"\x00\x01\x00\x00\x01\x00\x00\x00\x00"
    gid_a, gid_b = b"\xaa" * 16, b"\xbb" * 16
    for gid, seq in [(gid_a, 1), (gid_a, 2), (gid_a, 5), (gid_b, 10), (gid_a, 5), (gid_b, 11), (gid_a, 9)]:
        pub.put(payload, attachment=encode(seq, time.time_ns(), gid))
    wait_until(lambda: sub.stats.received == 7, timeout=5, message="7 samples")
    assert (sub.stats.gaps, sub.stats.missing, sub.stats.duplicates) == (2, 5, 1)
    assert sub.stats.delivered == 7
    assert [s.seq for s in samples if s.gid == gid_b] == [10, 11]


@pytest.mark.parametrize("ring", [None, 16], ids=["callback", "ring"])
def test_bad_traffic_is_counted_reported_and_never_stops_the_subscription(
    node: RosNode, raw: zenoh.Session, domain: int, ring: int | None
) -> None:
    samples: list[RosSample] = []
    errors: list[RoswireError] = []
    sub = node.create_subscriber(
        "/noisy", None, samples.append, decode=True, on_error=errors.append, ring=ring
    )
    key = data_key(domain, "/noisy", STRING, STRING_HASH)
    good_payload = b"\x00\x01\x00\x00\x03\x00\x00\x00ok\x00"
    good_att = encode(1, time.time_ns(), b"\x01" * 16)
    wait_until(
        lambda: raw.declare_publisher(key).matching_status.matching,  # type: ignore[attr-defined]
        timeout=5,
        message="subscriber matched",
    )
    raw.put(key, good_payload)  # no attachment
    raw.put(key, good_payload, attachment=b"\x01\x02\x03")  # broken attachment
    raw.put(key, good_payload, attachment=good_att[:16] + b"\x0f" + good_att[17:])  # bad gid length
    raw.put(key, b"\xde\xad\xbe\xef garbage", attachment=good_att)  # no CDR header
    raw.put(key, b"\x00\x01\x00\x00\xff\xff\xff\x7f", attachment=good_att)  # CDR header, does not decode
    raw.put(f"{domain}/noisy/not_a_type/xyz", good_payload, attachment=good_att)  # not a data key
    raw.put(key, good_payload, attachment=good_att)  # finally a good one
    wait_until(lambda: sub.stats.received == 7, timeout=5, message="all 7 samples seen")
    wait_until(lambda: len(samples) == 1, timeout=5, message="the good sample delivered")
    assert samples[0].message.data == "ok"
    stats = sub.stats
    assert (stats.no_attachment, stats.bad_attachment, stats.bad_payload, stats.bad_key) == (1, 2, 2, 1)
    assert stats.delivered == 1
    assert len(errors) == 6
    kinds = [type(e) for e in errors]
    assert kinds.count(AttachmentError) == 2
    assert kinds.count(PayloadError) == 3
    assert kinds.count(KeyParseError) == 1
    garbage = [e for e in errors if isinstance(e, PayloadError) and e.raw.startswith(b"\xde\xad")]
    assert len(garbage) == 1
    assert garbage[0].key == key
    undecodable = [e for e in errors if isinstance(e, PayloadError) and "does not decode" in e.reason]
    assert undecodable[0].key == key
    assert undecodable[0].typename == STRING
    broken = [e for e in errors if isinstance(e, AttachmentError)]
    assert {(e.key, e.payload) for e in broken} == {(key, good_payload)}  # the whole sample, for dead letters


def test_ring_subscriber_drains_a_burst_on_its_own_thread_in_order(
    node: RosNode, raw: zenoh.Session, domain: int
) -> None:
    threads: set[str] = set()
    seqs: list[int] = []

    def on_sample(sample: RosSample) -> None:
        threads.add(threading.current_thread().name)
        seqs.append(sample.seq or 0)

    sub = node.create_subscriber("/burst", STRING, on_sample, type_hash=STRING_HASH, ring=10_000)
    pub = node.create_publisher("/burst", STRING, type_hash=STRING_HASH)
    wait_until(lambda: pub.matching, timeout=5, message="matched")
    for _ in range(2000):
        pub.publish_cdr(b"\x00\x01\x00\x00\x01\x00\x00\x00\x00")
    wait_until(lambda: sub.stats.received == 2000, timeout=10, message="2000 samples")
    sub.stop()
    assert seqs == list(range(1, 2001))
    assert threads == {"recv/burst"}
    assert (sub.stats.gaps, sub.stats.delivered) == (0, 2000)


def test_ring_hands_over_bursts_with_on_samples(node: RosNode) -> None:
    bursts: list[list[RosSample]] = []
    sub = RosSubscriber(
        node, "/bursts", STRING, None, type_hash=STRING_HASH, ring=10_000, on_samples=bursts.append
    ).start()
    pub = node.create_publisher("/bursts", STRING, type_hash=STRING_HASH)
    wait_until(lambda: pub.matching, timeout=5, message="matched")
    for _ in range(2000):
        pub.publish_cdr(b"\x00\x01\x00\x00\x01\x00\x00\x00\x00")
    wait_until(lambda: sum(len(b) for b in bursts) == 2000, timeout=10, message="2000 samples in bursts")
    sub.stop()
    assert [s.seq for b in bursts for s in b] == list(range(1, 2001))
    assert max(len(b) for b in bursts) <= 256
    assert sub.stats.delivered == 2000


@pytest.mark.parametrize(
    ("callback", "on_samples", "ring", "reason"),
    [
        (print, None, 0, "at least one sample"),
        (None, None, 16, "give a callback"),
        (print, print, 16, "give a callback"),
        (None, print, None, "give a callback"),
    ],
)
def test_subscriber_arguments_that_cannot_work_are_refused(
    node: RosNode, callback: object, on_samples: object, ring: int | None, reason: str
) -> None:
    with pytest.raises(RoswireError, match=reason):
        RosSubscriber(node, "/x", STRING, callback, ring=ring, on_samples=on_samples)  # type: ignore[arg-type]


def test_callback_failure_does_not_stop_the_subscription(node: RosNode) -> None:
    calls: list[int] = []

    def flaky(sample: RosSample) -> None:
        calls.append(sample.seq or 0)
        if len(calls) == 1:
            raise RuntimeError("boom")

    sub = node.create_subscriber("/flaky", STRING, flaky, type_hash=STRING_HASH)
    pub = node.create_publisher("/flaky", STRING, type_hash=STRING_HASH)
    wait_until(lambda: pub.matching, timeout=5, message="matched")
    pub.publish_cdr(b"\x00\x01\x00\x00\x01\x00\x00\x00\x00")
    pub.publish_cdr(b"\x00\x01\x00\x00\x01\x00\x00\x00\x00")
    wait_until(lambda: calls == [1, 2], timeout=5, message="second sample after a failing callback")
    assert sub.stats.callback_errors == 1


def test_transient_local_late_joiner_gets_the_cached_sample(
    zenoh_router: str, domain: int, typestore: Typestore
) -> None:
    latched = b"\x00\x01\x00\x00\x07\x00\x00\x00map v1\x00"
    with RosNode(
        "map_server", domain_id=domain, config=zenoh_peer_config(zenoh_router), typestore=typestore
    ) as server:
        pub = server.create_publisher("/map_name", STRING, TRANSIENT_LOCAL)
        pub.publish_cdr(b"\x00\x01\x00\x00\x07\x00\x00\x00map v0\x00")
        pub.publish_cdr(latched)  # depth 1: only this one stays in the cache
        with RosNode(
            "late", domain_id=domain, config=zenoh_peer_config(zenoh_router), typestore=typestore
        ) as late:
            samples: list[RosSample] = []
            late.create_subscriber("/map_name", STRING, samples.append, TRANSIENT_LOCAL)
            wait_until(lambda: len(samples) >= 1, timeout=10, message="cached sample replayed")
            assert samples[0].payload == latched
            assert samples[0].seq == 2
            assert samples[0].gid == pub.gid
            # a volatile subscriber joining late sees nothing from the cache
            volatile: list[RosSample] = []
            late.create_subscriber("/map_name", STRING, volatile.append, type_hash=STRING_HASH)
            pub.publish_cdr(b"\x00\x01\x00\x00\x07\x00\x00\x00map v2\x00")
            wait_until(lambda: len(volatile) == 1 and len(samples) == 2, timeout=5, message="live sample")
            assert volatile[0].seq == 3


def test_best_effort_publisher_token_and_sensor_qos(node: RosNode, raw: zenoh.Session, domain: int) -> None:
    pub = node.create_publisher("imu", "sensor_msgs/msg/Imu", SENSOR_DATA)

    def publisher_tokens() -> list[str]:
        replies = raw.liveliness().get(f"@ros2_lv/{domain}/**", timeout=5)
        keys = [str(r.ok.key_expr) for r in replies if r.ok is not None]
        return [k for k in keys if "/MP/" in k]

    found: list[str] = []

    def one_token() -> bool:  # keep what answered: a second get may time out on a busy machine
        found[:] = publisher_tokens()
        return len(found) == 1

    wait_until(one_token, timeout=5, message="MP token answers a liveliness get")
    eps = [parse_token(k) for k in found]
    ep = eps[0]
    assert isinstance(ep, EndpointInfo)
    assert ep.qos == SENSOR_DATA
    assert ep.type_hash == "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b"
    assert ep.key.endswith("/2::,5:,:,:,,")
    assert ep.gid == pub.gid


def test_stopped_node_rejects_publishing(zenoh_router: str, domain: int) -> None:
    node = RosNode("short", domain_id=domain, config=zenoh_peer_config(zenoh_router)).start()
    pub = node.create_publisher("/x", STRING, type_hash=STRING_HASH)
    node.stop()
    with pytest.raises(RoswireError, match="not started"):
        pub.publish_cdr(b"\x00\x01\x00\x00")
    with pytest.raises(RoswireError, match="no type store"):
        RosNode("n", config=zenoh.Config()).type_hash(STRING)  # never started: no network needed


def test_probe_detects_an_older_network(zenoh_router: str, domain: int) -> None:
    with (
        RosNode(
            "old_talker", domain_id=domain, config=zenoh_peer_config(zenoh_router), attachment_version=1
        ) as old,
        RosNode("prober", domain_id=domain, config=zenoh_peer_config(zenoh_router)) as prober,
    ):
        pub = old.create_publisher("/chatter", STRING, type_hash="TypeHashNotSupported")
        stop = threading.Event()

        def talk() -> None:
            while not stop.wait(0.02):
                pub.publish_cdr(b"\x00\x01\x00\x00\x01\x00\x00\x00\x00")

        talker = threading.Thread(target=talk)
        talker.start()
        try:
            verdict = probe_wire(prober.session, domain, seconds=1.0)
        finally:
            stop.set()
            talker.join()
    assert verdict.attachment_version == 1
    assert verdict.hash_style == "humble"
    assert verdict.attachments.get("v1", 0) >= 10
    assert not verdict.mixed
