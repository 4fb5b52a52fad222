"""QoS in words: what ``ros graph`` prints and ``--qos`` takes, and echo's adapted profile."""

from __future__ import annotations

import pytest

from fleetlink.roswire.errors import QosParseError
from fleetlink.roswire.qos import (
    DEFAULT,
    SENSOR_DATA,
    TRANSIENT_LOCAL,
    Durability,
    QoS,
    Reliability,
    adapted,
    describe,
    parse_profile,
)


@pytest.mark.parametrize(
    ("qos", "text"),
    [
        (DEFAULT, "reliable, volatile, keep_last 10"),
        (SENSOR_DATA, "best_effort, volatile, keep_last 5"),
        (TRANSIENT_LOCAL, "reliable, transient_local, keep_last 1"),
        (QoS.parse("::2,:,:,:,,"), "reliable, volatile, keep_all"),
        (
            QoS.parse("::,:1,500000000:,:2,,"),
            "reliable, volatile, keep_last 42, deadline 1.5s, liveliness manual_by_node",
        ),
    ],
)
def test_describe(qos: QoS, text: str) -> None:
    assert describe(qos) == text


@pytest.mark.parametrize("qos", [DEFAULT, SENSOR_DATA, TRANSIENT_LOCAL])
def test_described_words_parse_back(qos: QoS) -> None:
    assert parse_profile(describe(qos)) == qos


def test_profiles_by_name() -> None:
    assert parse_profile("sensor_data") == SENSOR_DATA
    assert parse_profile(" Transient_Local ") == TRANSIENT_LOCAL


@pytest.mark.parametrize("text", ["fast", "keep_last", "keep_last x", "best_effort reliable"])
def test_unknown_words_are_refused(text: str) -> None:
    with pytest.raises(QosParseError, match="not a QoS setting"):
        parse_profile(text)


def test_adapting_to_publishers() -> None:
    assert adapted([]) == DEFAULT
    assert adapted([DEFAULT, SENSOR_DATA]).reliability == Reliability.BEST_EFFORT
    assert adapted([TRANSIENT_LOCAL]).durability == Durability.TRANSIENT_LOCAL
    assert adapted([TRANSIENT_LOCAL, DEFAULT]).durability == Durability.VOLATILE
