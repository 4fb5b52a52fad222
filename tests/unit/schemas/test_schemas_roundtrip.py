"""CDR -> Avro -> CDR is byte-identical, and decode() equals rosbags' decoding.

Values are generated with hypothesis for every message type of the jazzy store (plus the
iRobot Create 3 package), serialised with rosbags, converted and compared byte for byte.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from schemas.codec import get_codec
from schemas.typestore import load_typestore, message_types
from tests.unit.schemas.ros_values import avro_shaped, message, same

IROBOT = Path(__file__).resolve().parents[4] / "shared" / "data" / "msgs" / "irobot_create_msgs"
TS = load_typestore("jazzy", msg_paths=[IROBOT])
TYPES = message_types(TS)


def test_every_type_is_covered() -> None:
    assert len(TYPES) > 180
    assert "sensor_msgs/msg/PointCloud2" in TYPES
    assert "irobot_create_msgs/msg/LightringLeds" in TYPES


@pytest.mark.parametrize("typename", TYPES)
@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_round_trip(typename: str, data: st.DataObject) -> None:
    obj = data.draw(message(TS, typename))
    cdr = bytes(TS.serialize_cdr(obj, typename))
    codec = get_codec(TS, typename, "jazzy")
    avro = codec.cdr_to_avro(cdr)
    assert codec.avro_to_cdr(avro) == cdr
    # the Avro body is exactly what fastavro writes for the decoded datum
    decoded = codec.decode(cdr)
    assert codec.encode_datum(decoded) == avro
    assert same(decoded, codec.read_avro(avro))
    assert same(decoded, avro_shaped(TS, TS.deserialize_cdr(cdr, typename), typename))
    # big-endian input gives the same record
    big = bytes(TS.serialize_cdr(obj, typename, little_endian=False))
    assert codec.cdr_to_avro(big) == avro
    assert same(codec.decode(big), decoded)
