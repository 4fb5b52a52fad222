"""Which topics the edge subscribes, and with which type (pure planning)."""

from __future__ import annotations

import pytest

from fleetlink.edge.mapping import MappingSpec, MappingTable, RobotTypeSpec
from fleetlink.edge.runtime.subscriptions import eager_topics, plan

IMU = "sensor_msgs/msg/Imu"
STRING = "std_msgs/msg/String"
GRID = "nav_msgs/msg/OccupancyGrid"
TB4 = RobotTypeSpec(
    "turtlebot4",
    "/tb4_*",
    (
        MappingSpec(name="imu", source="/{robot}/imu", topic="fleet.imu", ros_type=IMU),
        MappingSpec(name="odom", source="/{robot}/odom", topic="fleet.odom"),
    ),
)
SITE = (
    MappingSpec(name="any", source="/{robot}/status/{what}", topic="fleet.status.{what}"),
    MappingSpec(name="map", source="/map", topic="site.map", key="site", ros_type=GRID),
)


def table(*robots: str) -> MappingTable:
    t = MappingTable([TB4], SITE)
    for robot in robots:
        t.add_robot(robot)
    return t


def test_eager_topics_of_declared_types() -> None:
    assert eager_topics(table()) == {"/map": "nav_msgs/msg/OccupancyGrid"}
    assert eager_topics(table("tb4_01", "tb4_02")) == {
        "/map": "nav_msgs/msg/OccupancyGrid",
        "/tb4_01/imu": IMU,
        "/tb4_02/imu": IMU,
    }


@pytest.mark.parametrize(
    ("publishers", "robots", "wanted"),
    [
        # nothing published, no robot: only the eager site topic
        ({}, (), {"/map": "nav_msgs/msg/OccupancyGrid"}),
        # a robot's topics: declared type wins, else the announced one; unmapped topics are ignored
        (
            {"/tb4_01/imu": {IMU}, "/tb4_01/odom": {"nav_msgs/msg/Odometry"}, "/tb4_01/cmd_vel": {"x/msg/T"}},
            ("tb4_01",),
            {
                "/map": "nav_msgs/msg/OccupancyGrid",
                "/tb4_01/imu": IMU,
                "/tb4_01/odom": "nav_msgs/msg/Odometry",
            },
        ),
        # a robot not registered: its robot-type topics are not wanted, site patterns are
        (
            {"/tb4_09/odom": {"nav_msgs/msg/Odometry"}, "/tb4_09/status/battery": {STRING}},
            (),
            {"/map": "nav_msgs/msg/OccupancyGrid", "/tb4_09/status/battery": STRING},
        ),
        # publishers disagree on the type: subscribe to any type
        ({"/r1/status/x": {STRING, IMU}}, (), {"/map": "nav_msgs/msg/OccupancyGrid", "/r1/status/x": None}),
        # a declared type is subscribed even when a publisher announces another
        ({"/tb4_01/imu": {STRING}}, ("tb4_01",), {"/map": "nav_msgs/msg/OccupancyGrid", "/tb4_01/imu": IMU}),
    ],
)
def test_plan(
    publishers: dict[str, set[str]], robots: tuple[str, ...], wanted: dict[str, str | None]
) -> None:
    assert plan(publishers, table(*robots)) == wanted


def test_mappings_declaring_different_types_on_one_topic_subscribe_to_any() -> None:
    t = MappingTable(
        [],
        [
            MappingSpec(name="a", source="/x", topic="a", key="k", ros_type=IMU),
            MappingSpec(name="b", source="/x", topic="b", key="k", ros_type=STRING),
        ],
    )
    assert plan({}, t) == {"/x": None}
