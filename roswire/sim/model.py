"""The pure model of one simulated TurtleBot 4 / Create 3: pose, sensors, battery, faults, LEDs.

No clock and no I/O: :meth:`RobotModel.step` takes ``now`` (seconds since the Unix epoch) and
returns the readings; noise comes from a seeded ``random.Random``. The "picked up" fault is
what the fault-detection scenario looks for: kidnap status true, IR intensities high, wheels
dropped, the robot standing still.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

IR_SENSORS = (
    "ir_intensity_side_left",
    "ir_intensity_left",
    "ir_intensity_front_left",
    "ir_intensity_front_center_left",
    "ir_intensity_front_center_right",
    "ir_intensity_front_right",
    "ir_intensity_right",
)
IR_NORMAL_MAX = 300
IR_PICKED_UP_MIN = 3000
IR_PICKED_UP_MAX = 4000

HAZARD_BUMP = 1
HAZARD_CLIFF = 2
HAZARD_WHEEL_DROP = 4

LINEAR_SPEED = 0.2  # m/s, driving a circle
ANGULAR_SPEED = 0.25  # rad/s
BATTERY_DRAIN_PER_S = 1.0 / 60 / 100  # 1 % per minute
GRAVITY = 9.80665
LED_COUNT = 6

RGB = tuple[int, int, int]

_NAMED: dict[RGB, str] = {
    (0, 0, 0): "off",
    (255, 0, 0): "red",
    (0, 255, 0): "green",
    (0, 0, 255): "blue",
    (255, 255, 0): "yellow",
    (255, 255, 255): "white",
    (255, 165, 0): "orange",
    (0, 255, 255): "cyan",
    (255, 0, 255): "magenta",
}


def colour_name(rgb: RGB) -> str:
    """A readable name for an LED colour (``#rrggbb`` when it has no common name)."""
    return _NAMED.get(rgb, "#{:02x}{:02x}{:02x}".format(*rgb))


@dataclass(frozen=True)
class LedState:
    """The colours the light ring shows, whether a command overrides the system's, and since when."""

    colours: tuple[RGB, ...]
    override_system: bool
    at: float

    @property
    def name(self) -> str:
        """One name when all LEDs agree, else the names joined by ``,``."""
        names = [colour_name(c) for c in self.colours]
        return names[0] if len(set(names)) == 1 else ",".join(names)


SYSTEM_LEDS = LedState(((0, 255, 0),) * LED_COUNT, override_system=False, at=0.0)
"""What the robot shows when nobody overrides its light ring (idle and healthy: green)."""


@dataclass(frozen=True)
class Readings:
    """What the robot's sensors report at ``stamp``: IR, hazards, kidnap, pose, motion, battery."""

    stamp: float
    ir: tuple[int, ...]
    hazards: tuple[int, ...]
    kidnapped: bool
    x: float
    y: float
    yaw: float
    linear_velocity: float
    angular_velocity: float
    linear_acceleration: tuple[float, float, float]
    battery_percentage: float
    battery_voltage: float


@dataclass
class RobotModel:
    """The state of one simulated robot: pose, faults, dock, motors, battery and light ring."""

    name: str
    start: float
    seed: int = 0
    picked_up: bool = False
    docked: bool = False
    e_stop: bool = False
    motors_enabled: bool = True
    drive_left: float = 0.0
    """Metres a DriveDistance goal still has to go (straight ahead, instead of the circle)."""
    pictures: int = 0
    led: LedState = SYSTEM_LEDS
    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0
    battery: float = 1.0
    _last: float | None = field(default=None, repr=False)
    _rng: random.Random = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._rng = random.Random(f"{self.name}:{self.seed}")

    def inject_fault(self) -> None:
        """The robot is picked up."""
        self.picked_up = True

    def heal(self) -> None:
        """The robot is put back on the floor."""
        self.picked_up = False

    def dock(self) -> None:
        """The robot is on its dock (at the origin), standing still, back on the floor."""
        self.docked, self.picked_up, self.drive_left = True, False, 0.0
        self.x = self.y = 0.0

    def undock(self) -> None:
        """The robot leaves its dock and may drive again."""
        self.docked = False

    def reset_pose(self, x: float, y: float, yaw: float) -> None:
        """Put the robot at ``x``, ``y`` (metres) facing ``yaw`` (radians)."""
        self.x, self.y, self.yaw = x, y, yaw

    @property
    def can_drive(self) -> bool:
        """Whether the robot moves: on the floor, off its dock, no e-stop, motors enabled."""
        return not (self.picked_up or self.docked or self.e_stop or not self.motors_enabled)

    def set_lightring(self, colours: tuple[RGB, ...], override_system: bool, now: float) -> LedState:
        """Apply a ``cmd_lightring`` command: overriding colours show, otherwise the system's."""
        self.led = (
            LedState(colours, True, now) if override_system else LedState(SYSTEM_LEDS.colours, False, now)
        )
        return self.led

    def step(self, now: float) -> Readings:
        """Advance the robot to ``now`` (Unix seconds) and return its readings.

        It drives a circle, or straight ahead while a DriveDistance goal has distance left, unless it
        cannot drive; the battery drains with time whatever it does.
        """
        dt = 0.0 if self._last is None else max(0.0, now - self._last)
        self._last = now
        rng = self._rng
        if not self.can_drive:
            v, w = 0.0, 0.0
        elif self.drive_left > 0:
            v, w = LINEAR_SPEED, 0.0
            self.drive_left = max(0.0, self.drive_left - v * dt)
        else:
            v, w = LINEAR_SPEED, ANGULAR_SPEED
        self.yaw = (self.yaw + w * dt + math.pi) % (2 * math.pi) - math.pi
        self.x += v * math.cos(self.yaw) * dt
        self.y += v * math.sin(self.yaw) * dt
        self.battery = max(0.0, self.battery - BATTERY_DRAIN_PER_S * dt)
        if self.picked_up:
            ir = tuple(rng.randint(IR_PICKED_UP_MIN, IR_PICKED_UP_MAX) for _ in IR_SENSORS)
            hazards: tuple[int, ...] = (HAZARD_WHEEL_DROP, HAZARD_CLIFF)
            accel = (rng.gauss(0, 0.8), rng.gauss(0, 0.8), GRAVITY + rng.gauss(0, 1.5))
        else:
            ir = tuple(rng.randint(0, IR_NORMAL_MAX) for _ in IR_SENSORS)
            hazards = ()
            accel = (rng.gauss(0, 0.02), v * w + rng.gauss(0, 0.02), GRAVITY + rng.gauss(0, 0.02))
        return Readings(
            stamp=now,
            ir=ir,
            hazards=hazards,
            kidnapped=self.picked_up,
            x=self.x,
            y=self.y,
            yaw=self.yaw,
            linear_velocity=v,
            angular_velocity=w,
            linear_acceleration=accel,
            battery_percentage=self.battery,
            battery_voltage=14.0 + 2.8 * self.battery,
        )
