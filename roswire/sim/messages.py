"""Turn :class:`~roswire.sim.model.Readings` into ROS messages (rosbags objects), and back for
the light ring. Pure: needs only a type store holding the standard and Create 3 types."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from fleetlink.roswire.sim.model import IR_SENSORS, RGB, Readings

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

IR_VECTOR = "irobot_create_msgs/msg/IrIntensityVector"
HAZARDS = "irobot_create_msgs/msg/HazardDetectionVector"
KIDNAP = "irobot_create_msgs/msg/KidnapStatus"
LIGHTRING = "irobot_create_msgs/msg/LightringLeds"
ODOMETRY = "nav_msgs/msg/Odometry"
IMU = "sensor_msgs/msg/Imu"
BATTERY = "sensor_msgs/msg/BatteryState"
IMAGE = "sensor_msgs/msg/Image"
CAMERA_TOPIC = "oakd/rgb/preview/image_raw"
"""A TurtleBot 4's camera (OAK-D preview: 250x250 rgb8), under the robot's namespace."""
CAMERA_SIZE = 250

_HAZARD_FRAMES = {1: "bump_front_center", 2: "cliff_front_left", 4: "wheel_drop_left"}


class MessageFactory:
    """Builds one robot's Create 3 messages (rosbags objects) from model readings."""

    def __init__(self, ts: Typestore, robot: str) -> None:
        self.ts = ts
        self.robot = robot
        self.t = ts.types

    def header(self, stamp: float, frame: str) -> Any:
        """A ``std_msgs/msg/Header`` stamped ``stamp`` (Unix seconds) in frame ``frame``."""
        sec = math.floor(stamp)
        nanosec = min(round((stamp - sec) * 1e9), 999_999_999)
        return self.t["std_msgs/msg/Header"](
            stamp=self.t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=frame
        )

    def camera_image(self, stamp: float, number: int) -> Any:
        """A 250x250 rgb8 picture: a gradient tinted by the robot's name, with noise, and a bar as
        wide as the picture's number (so two pictures differ)."""
        size = CAMERA_SIZE
        y, x = np.mgrid[0:size, 0:size]
        tint = sum(self.robot.encode()) % 128
        pixels = np.stack([x * 255 // size, y * 255 // size, np.full_like(x, tint)], -1)
        rng = np.random.default_rng(number)
        pixels = (pixels + rng.integers(0, 6, pixels.shape)).clip(0, 255).astype(np.uint8)
        pixels[: size // 10, : min(size, 10 * number)] = 255
        return self.t[IMAGE](
            header=self.header(stamp, "oakd_rgb_camera_optical_frame"),
            height=size,
            width=size,
            encoding="rgb8",
            is_bigendian=0,
            step=size * 3,
            data=pixels.reshape(-1),
        )

    def ir_intensity(self, r: Readings) -> Any:
        """The ``IrIntensityVector`` of the readings: one reading per IR sensor."""
        readings = [
            self.t["irobot_create_msgs/msg/IrIntensity"](header=self.header(r.stamp, name), value=value)
            for name, value in zip(IR_SENSORS, r.ir, strict=True)
        ]
        return self.t[IR_VECTOR](header=self.header(r.stamp, "base_link"), readings=readings)

    def hazard_detection(self, r: Readings) -> Any:
        """The ``HazardDetectionVector`` of the readings: one detection per hazard (none on the floor)."""
        detections = [
            self.t["irobot_create_msgs/msg/HazardDetection"](
                header=self.header(r.stamp, _HAZARD_FRAMES.get(h, "base_link")), type=h
            )
            for h in r.hazards
        ]
        return self.t[HAZARDS](header=self.header(r.stamp, "base_link"), detections=detections)

    def kidnap_status(self, r: Readings) -> Any:
        """The ``KidnapStatus`` of the readings (kidnapped while picked up)."""
        return self.t[KIDNAP](header=self.header(r.stamp, "base_link"), is_kidnapped=r.kidnapped)

    def _vec(self, x: float, y: float, z: float) -> Any:
        return self.t["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)

    def _quat(self, yaw: float) -> Any:
        return self.t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))

    def odom(self, r: Readings) -> Any:
        """The ``nav_msgs/msg/Odometry`` of the readings: pose and velocities, zero covariances."""
        t = self.t
        pose = t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=r.x, y=r.y, z=0.0), orientation=self._quat(r.yaw)
        )
        twist = t["geometry_msgs/msg/Twist"](
            linear=self._vec(r.linear_velocity, 0.0, 0.0), angular=self._vec(0.0, 0.0, r.angular_velocity)
        )
        cov = np.zeros(36, dtype=np.float64)
        return t[ODOMETRY](
            header=self.header(r.stamp, "odom"),
            child_frame_id="base_link",
            pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
            twist=t["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov.copy()),
        )

    def imu(self, r: Readings) -> Any:
        """The ``sensor_msgs/msg/Imu`` of the readings: heading, turn rate and acceleration."""
        cov = np.zeros(9, dtype=np.float64)
        return self.t[IMU](
            header=self.header(r.stamp, "imu_link"),
            orientation=self._quat(r.yaw),
            orientation_covariance=cov,
            angular_velocity=self._vec(0.0, 0.0, r.angular_velocity),
            angular_velocity_covariance=cov.copy(),
            linear_acceleration=self._vec(*r.linear_acceleration),
            linear_acceleration_covariance=cov.copy(),
        )

    def battery_state(self, r: Readings) -> Any:
        """The ``sensor_msgs/msg/BatteryState`` of the readings (a discharging Li-ion pack)."""
        cls: Any = self.t[BATTERY]
        return cls(
            header=self.header(r.stamp, "base_link"),
            voltage=r.battery_voltage,
            temperature=25.0,
            current=-0.5,
            charge=2.1 * r.battery_percentage,
            capacity=2.1,
            design_capacity=2.1,
            percentage=r.battery_percentage,
            power_supply_status=cls.POWER_SUPPLY_STATUS_DISCHARGING,
            power_supply_health=cls.POWER_SUPPLY_HEALTH_GOOD,
            power_supply_technology=cls.POWER_SUPPLY_TECHNOLOGY_LION,
            present=True,
            cell_voltage=np.zeros(0, dtype=np.float32),
            cell_temperature=np.zeros(0, dtype=np.float32),
            location="slot0",
            serial_number=f"{self.robot}-battery",
        )

    def lightring(self, colours: tuple[RGB, ...], override_system: bool, stamp: float) -> Any:
        """A ``cmd_lightring`` command (what a fleet operator would send)."""
        leds = [self.t["irobot_create_msgs/msg/LedColor"](red=r, green=g, blue=b) for r, g, b in colours]
        return self.t[LIGHTRING](
            header=self.header(stamp, "base_link"), leds=leds, override_system=override_system
        )


def lightring_colours(msg: Any) -> tuple[RGB, ...]:
    """The (red, green, blue) of each LED in a ``LightringLeds`` message."""
    return tuple((int(c.red), int(c.green), int(c.blue)) for c in msg.leds)
