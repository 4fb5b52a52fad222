"""CDR -> Avro -> CDR is byte-identical, and decode() equals rosbags' decoding.

Values are generated with hypothesis for every message type of the jazzy store (plus the
iRobot Create 3 package), serialised with rosbags, converted and compared byte for byte.
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fleetlink.schemas.codec import get_codec
from fleetlink.schemas.typestore import load_typestore, message_types, types_from_msg
from tests.paths import IROBOT
from tests.unit.schemas.ros_values import avro_shaped, message, same

TS = load_typestore("jazzy", msg_paths=[IROBOT])
# Layouts the standard types rarely combine: alignment after variable parts inside loops,
# fixed arrays of records with strings, bounded everything, sequences first and last.
TORTURE = {
    "t_msgs/msg/Inner": "uint8 a\nfloat64 b\nstring s\nint16[] c\nbool[2] flags\n",
    "t_msgs/msg/Outer": (
        "bool f\nInner[3] fixed\nInner[] seq\nInner[<=2] bounded\nstring[2] names\n"
        "string<=3[<=2] short_names\nfloat64[] ds\nuint8 tail\nbyte[] raw\nchar[3] chars\n"
        "uint64[] bigs\nint8 last\nfloat32[<=4] fs\nuint32[2] pair\nInner single\n"
    ),
    "t_msgs/msg/SequenceFirst": "float64[] xs\nuint8 after\nint64[] ys\n",
    "t_msgs/msg/OnlyStrings": "string a\nstring<=2 b\nstring[] c\n",
}
for _name, _text in TORTURE.items():
    TS.register(types_from_msg(_text, _name))
TYPES = message_types(TS)


def test_every_type_is_covered() -> None:
    assert len(TYPES) > 180
    assert "sensor_msgs/msg/PointCloud2" in TYPES
    assert "irobot_create_msgs/msg/LightringLeds" in TYPES
    assert set(TORTURE) <= set(TYPES)


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
