"""Pure parts of the bag replayer: topic prefixing, QoS from bag metadata, timing."""

from __future__ import annotations

import pytest
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

from fleetlink.roswire.errors import InvalidNameError
from fleetlink.roswire.qos import DEFAULT, Durability, History, QoS, Reliability
from fleetlink.roswire.replay import ReplaySchedule, qos_from_bag, robot_topic

FOREVER = QosTime(sec=2147483647, nsec=4294967295)


def profile(history: QosHistory, depth: int, reliability: QosReliability, durability: QosDurability) -> Qos:
    return Qos(
        history=history,
        depth=depth,
        reliability=reliability,
        durability=durability,
        deadline=FOREVER,
        lifespan=FOREVER,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=FOREVER,
        avoid_ros_namespace_conventions=False,
    )


@pytest.mark.parametrize(
    ("robot", "topic", "out"),
    [("tb4_01", "/imu/data", "/tb4_01/imu/data"), ("husky", "/tf", "/husky/tf"), ("r", "odom", "/r/odom")],
)
def test_robot_topic(robot: str, topic: str, out: str) -> None:
    assert robot_topic(robot, topic) == out


@pytest.mark.parametrize(("robot", "topic"), [("a/b", "/x"), ("", "/x"), ("r", "/")])
def test_robot_topic_rejects(robot: str, topic: str) -> None:
    with pytest.raises(InvalidNameError):
        robot_topic(robot, topic)


@pytest.mark.parametrize(
    ("profiles", "qos"),
    [
        ([], DEFAULT),
        # what rosbags-convert wrote for the turtlebot3 bag's /cmd_vel (latched in ROS 1)
        (
            [profile(QosHistory.UNKNOWN, 0, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL)],
            QoS(durability=Durability.TRANSIENT_LOCAL, depth=10),
        ),
        (
            [profile(QosHistory.KEEP_LAST, 5, QosReliability.BEST_EFFORT, QosDurability.VOLATILE)],
            QoS(reliability=Reliability.BEST_EFFORT, depth=5),
        ),
        (
            [profile(QosHistory.KEEP_ALL, 1000, QosReliability.RELIABLE, QosDurability.VOLATILE)],
            QoS(history=History.KEEP_ALL, depth=1000),
        ),
    ],
)
def test_qos_from_bag(profiles: list[Qos], qos: QoS) -> None:
    assert qos_from_bag(profiles) == qos


@pytest.mark.parametrize(
    ("rate", "stamp_ns", "due"),
    [
        (1.0, 1_000_000_000, 100.0),
        (1.0, 3_500_000_000, 102.5),
        (2.0, 3_000_000_000, 101.0),
        (0.5, 2_000_000_000, 102.0),
        (0.0, 90_000_000_000, 100.0),
    ],
)
def test_schedule(rate: float, stamp_ns: int, due: float) -> None:
    assert ReplaySchedule(first_ns=1_000_000_000, start=100.0, rate=rate).due(stamp_ns) == pytest.approx(due)
