"""What the edge receives: one wildcard key expression per mapping pattern, not one per topic."""

from __future__ import annotations

import zenoh

from fleetlink.edge.mapping import MappingSpec, MappingTable
from fleetlink.edge.mapping.spec import RobotTypeSpec
from fleetlink.edge.runtime.subscriptions import receive_keys

IMU = "sensor_msgs/msg/Imu"


def table() -> MappingTable:
    tb4 = RobotTypeSpec(
        "tb4",
        "/tb4_*",
        (
            MappingSpec(name="imu", source="/{robot}/imu", topic="fleet.imu", ros_type=IMU),
            MappingSpec(name="any", source="/{robot}/sensors/{sensor}", topic="fleet.{sensor}"),
        ),
    )
    site = MappingSpec(name="map", source="/map/{rest*}", topic="site.map", key="{rest}")
    return MappingTable([tb4], [site])


def test_one_key_per_pattern_whatever_the_number_of_robots() -> None:
    t = table()
    keys = receive_keys(t, 7)
    assert keys == {
        "7/tb4_$*/imu/sensor_msgs::msg::dds_::Imu_/*",
        "7/tb4_$*/sensors/*/*/*",
        "7/map/*/*/**",  # (Zenoh's canonical form of 7/map/**/*/*)
    }
    for n in range(500):
        t.add_robot(f"tb4_{n:03d}")
    assert receive_keys(t, 7) == keys


def test_a_robot_registered_outside_its_glob_gets_exact_keys() -> None:
    t = table()
    t.add_robot("special", "tb4")
    assert "7/special/imu/sensor_msgs::msg::dds_::Imu_/*" in receive_keys(t, 7)


def test_the_keys_match_the_data_keys_of_the_topics_they_stand_for() -> None:
    keys = [zenoh.KeyExpr(k) for k in receive_keys(table(), 7)]
    hash_ = "RIHS01_" + "a" * 64

    def received(key: str) -> bool:
        return any(k.intersects(zenoh.KeyExpr(key)) for k in keys)

    assert received(f"7/tb4_01/imu/sensor_msgs::msg::dds_::Imu_/{hash_}")
    assert received(f"7/tb4_01/sensors/lidar/sensor_msgs::msg::dds_::LaserScan_/{hash_}")
    assert received(f"7/map/a/b/nav_msgs::msg::dds_::OccupancyGrid_/{hash_}")
    assert not received(f"7/tb3_01/imu/sensor_msgs::msg::dds_::Imu_/{hash_}")  # another robot type
    assert not received(f"7/tb4_01/odom/nav_msgs::msg::dds_::Odometry_/{hash_}")  # not mapped
    assert not received(f"8/tb4_01/imu/sensor_msgs::msg::dds_::Imu_/{hash_}")  # another domain
