"""Every message of the two real bags: CDR -> Avro -> CDR byte-identical, values as rosbags reads them."""

from __future__ import annotations

from collections import Counter

import pytest
from rosbags.rosbag2 import Reader

from fleetlink.schemas.codec import get_codec
from fleetlink.schemas.typestore import load_typestore
from tests.paths import BAGS
from tests.unit.schemas.ros_values import avro_shaped, same

EXPECTED = {
    "robot_localization_husky": {
        "sensor_msgs/msg/Imu": 11865,
        "nav_msgs/msg/Odometry": 3952,
        "sensor_msgs/msg/NavSatFix": 989,
    },
    "fuse_turtlebot3_sim": {
        "sensor_msgs/msg/LaserScan": 457,
        "sensor_msgs/msg/Imu": 2253,
        "nav_msgs/msg/Odometry": 2741,
        "sensor_msgs/msg/JointState": 2741,
        "geometry_msgs/msg/Twist": 2335,
    },
}


@pytest.mark.parametrize("bag", sorted(EXPECTED))
def test_every_message_round_trips(bag: str) -> None:
    ts = load_typestore("humble", bags=[BAGS / bag])
    seen: Counter[str] = Counter()
    with Reader(BAGS / bag) as reader:
        for conn, _, raw in reader.messages():
            cdr = bytes(raw)
            codec = get_codec(ts, conn.msgtype, "humble")
            avro = codec.cdr_to_avro(cdr)
            assert codec.avro_to_cdr(avro) == cdr, (conn.topic, seen[conn.msgtype])
            expected = avro_shaped(ts, ts.deserialize_cdr(cdr, conn.msgtype), conn.msgtype)
            assert same(codec.decode(cdr), expected)
            seen[conn.msgtype] += 1
    assert dict(seen) == EXPECTED[bag]
