"""Messages from and to plain data (``ros pub`` and ``ros echo``), errors by field path."""

from __future__ import annotations

from typing import Any

import pytest
from rosbags.typesys.store import Typestore

from fleetlink.schemas.messages import MessageDataError, from_data, to_data
from fleetlink.schemas.typestore import load_typestore


@pytest.fixture(scope="module")
def ts() -> Typestore:
    return load_typestore("jazzy")


def _roundtrip(ts: Typestore, typename: str, data: Any) -> Any:
    raw = ts.serialize_cdr(from_data(ts, typename, data), typename)
    return to_data(ts.deserialize_cdr(raw, typename))


def test_given_fields_travel_and_the_rest_default(ts: Typestore) -> None:
    out = _roundtrip(ts, "irobot_create_msgs/msg/LightringLeds", {"leds": [{"red": 255}] * 6})
    assert out["leds"][0] == {"red": 255, "green": 0, "blue": 0}
    assert out["override_system"] is False
    assert out["header"] == {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""}


def test_arrays_sequences_and_bytes(ts: Typestore) -> None:
    out = _roundtrip(ts, "sensor_msgs/msg/Imu", {"orientation_covariance": [1, 2, 3, 4, 5, 6, 7, 8, 9]})
    assert out["orientation_covariance"] == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]
    assert _roundtrip(ts, "std_msgs/msg/UInt8MultiArray", {"data": [1, 2, 255]})["data"] == [1, 2, 255]
    assert _roundtrip(ts, "std_msgs/msg/String", {"data": "héllo"}) == {"data": "héllo"}


def test_empty_messages_and_service_halves(ts: Typestore) -> None:
    assert _roundtrip(ts, "std_srvs/srv/Trigger_Request", None) == {"structure_needs_at_least_one_member": 0}
    assert _roundtrip(ts, "example_interfaces/srv/AddTwoInts_Request", {"a": 2, "b": 3}) == {"a": 2, "b": 3}


@pytest.mark.parametrize(
    ("typename", "data", "message"),
    [
        ("std_msgs/msg/String", {"dat": "x"}, "no field 'dat' (fields: data)"),
        ("std_msgs/msg/UInt8", {"data": 256}, "data: expected an integer in 0..255"),
        ("std_msgs/msg/Bool", {"data": "yes"}, "data: expected true or false"),
        (
            "sensor_msgs/msg/Imu",
            {"orientation_covariance": [1]},
            "orientation_covariance: expected 9 items, got 1",
        ),
        (
            "irobot_create_msgs/msg/LightringLeds",
            {"leds": [{"red": -1}] * 6},
            "leds[0].red: expected an integer",
        ),
        ("std_msgs/msg/Header", {"stamp": 5}, "stamp: expected a mapping"),
        ("std_msgs/msg/String", ["x"], "the message: expected a mapping"),
    ],
)
def test_bad_data_names_the_field(ts: Typestore, typename: str, data: Any, message: str) -> None:
    with pytest.raises(MessageDataError) as info:
        from_data(ts, typename, data)
    assert message in str(info.value)
    assert str(info.value).startswith(typename)
