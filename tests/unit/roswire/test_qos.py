"""Compact QoS strings: default elision exactly as rmw_zenoh writes them (rmw_zenoh.md §3)."""

from __future__ import annotations

import pytest

from fleetlink.roswire.errors import QosParseError
from fleetlink.roswire.qos import (
    DEFAULT,
    INFINITE,
    SENSOR_DATA,
    SERVICES,
    TRANSIENT_LOCAL,
    Durability,
    Duration,
    History,
    Liveliness,
    QoS,
    Reliability,
)

CASES: list[tuple[str, QoS, str]] = [
    ("rclcpp::QoS(10)", DEFAULT, "::,10:,:,:,,"),
    ("sensor data", SENSOR_DATA, "2::,5:,:,:,,"),
    ("tf_static", TRANSIENT_LOCAL, ":1:,1:,:,:,,"),
    ("services", SERVICES, "::,10:,:,:,,"),
    ("talker depth 7", QoS(depth=7), "::,7:,:,:,,"),
    ("all rmw_zenoh defaults", QoS(depth=42), "::,:,:,:,,"),
    ("keep all", QoS(history=History.KEEP_ALL, depth=1000), "::2,1000:,:,:,,"),
    ("deadline 1.5 s", QoS(deadline=Duration(1, 500_000_000)), "::,10:1,500000000:,:,,"),
    ("lifespan 0 s", QoS(lifespan=Duration(0, 0)), "::,10:,:0,0:,,"),
    (
        "manual by topic, lease 2 s",
        QoS(liveliness=Liveliness.MANUAL_BY_TOPIC, lease=Duration(2, 0)),
        "::,10:,:,:3,2,0",
    ),
    ("lease seconds only differ", QoS(lease=Duration(5, INFINITE.nsec)), "::,10:,:,:,5,"),
    (
        "best effort transient local",
        QoS(Reliability.BEST_EFFORT, Durability.TRANSIENT_LOCAL, depth=3),
        "2:1:,3:,:,:,,",
    ),
]


@pytest.mark.parametrize(("label", "qos", "text"), CASES, ids=[c[0] for c in CASES])
def test_qos_to_keyexpr_and_back(label: str, qos: QoS, text: str) -> None:
    assert qos.to_keyexpr() == text, label
    assert QoS.parse(text) == qos


def test_parse_fills_rmw_zenoh_defaults() -> None:
    parsed = QoS.parse("::,:,:,:,,")
    assert parsed.depth == 42
    assert parsed.reliability is Reliability.RELIABLE
    assert parsed.durability is Durability.VOLATILE
    assert parsed.deadline.is_infinite
    assert parsed.lease.to_ns() == 2**63 - 1


def test_parse_ignores_extra_fields_like_rmw_zenoh() -> None:
    assert QoS.parse("::,10:,:,:,,:extra") == DEFAULT
    assert QoS.parse("::,10,7:,,9:,:,,,x") == DEFAULT


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("::,10:,:,", "6"),
        ("", "6"),
        ("::10:,:,:,,", "history"),
        ("::,10:,:,:,", "liveliness"),
        ("::,10:1:,:,,", "deadline field .1."),
        ("x::,10:,:,:,,", "reliability"),
        ("9::,10:,:,:,,", "reliability 9"),
        ("::,-1:,:,:,,", "depth"),
        ("::,10:a,:,:,,", "deadline"),
        ("::,10:5:,:,,", "deadline field '5'"),
    ],
)
def test_parse_rejects(text: str, reason: str) -> None:
    with pytest.raises(QosParseError, match=reason) as info:
        QoS.parse(text)
    assert info.value.text == text


def test_flags() -> None:
    assert TRANSIENT_LOCAL.transient_local
    assert not DEFAULT.transient_local
    assert SENSOR_DATA.best_effort
    assert not DEFAULT.best_effort
    assert DEFAULT.with_depth(3).to_keyexpr() == "::,3:,:,:,,"
