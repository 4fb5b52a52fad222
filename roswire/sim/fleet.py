"""Run simulated TurtleBot 4 robots on zenoh, each as its own rmw_zenoh process would.

Each robot gets its own session and a node ``/<name>/create3`` publishing ``ir_intensity``,
``hazard_detection``, ``kidnap_status``, ``odom``, ``imu`` and ``battery_state``, subscribing
to ``cmd_lightring`` and serving the services and actions of :mod:`roswire.sim.services`
(``e_stop``, ``take_picture``, ``dock`` …). Robots can be added, removed, picked up (fault)
and healed while running.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from types import TracebackType
from typing import TYPE_CHECKING, Any

import zenoh

from fleetlink.roswire.errors import RoswireError
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.publisher import RosPublisher
from fleetlink.roswire.qos import DEFAULT, SENSOR_DATA, QoS
from fleetlink.roswire.sim.messages import (
    BATTERY,
    HAZARDS,
    IMU,
    IR_VECTOR,
    KIDNAP,
    LIGHTRING,
    ODOMETRY,
    MessageFactory,
    lightring_colours,
)
from fleetlink.roswire.sim.model import LedState, RobotModel
from fleetlink.roswire.sim.services import DEFAULT_TIMING, EventListener, RobotServices, Timing
from fleetlink.roswire.subscriber import RosSample
from fleetlink.schemas.typestore import Distro

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

log = logging.getLogger(__name__)

# topic -> (type, QoS); every topic goes out each tick except battery_state (about 1 Hz).
TOPICS: dict[str, tuple[str, QoS]] = {
    "ir_intensity": (IR_VECTOR, SENSOR_DATA),
    "hazard_detection": (HAZARDS, SENSOR_DATA),
    "kidnap_status": (KIDNAP, DEFAULT),
    "odom": (ODOMETRY, SENSOR_DATA),
    "imu": (IMU, SENSOR_DATA),
    "battery_state": (BATTERY, DEFAULT),
}
LedListener = Callable[[str, LedState], object]


@dataclass
class SimRobot:
    """One simulated robot: model, node, publishers and services; ``lock`` guards the model and publishing."""

    name: str
    model: RobotModel
    node: RosNode
    factory: MessageFactory
    publishers: dict[str, RosPublisher] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)
    ticks: int = 0
    stopped: bool = False
    services: RobotServices | None = None


class Fleet:
    """Simulated TurtleBot 4 robots, each with its own session, ticking at ``rate`` Hz on one thread."""

    def __init__(
        self,
        config: zenoh.Config,
        typestore: Typestore,
        *,
        robots: int = 3,
        prefix: str = "tb4_",
        rate: float = 10.0,
        domain_id: int = 0,
        distro: Distro = "jazzy",
        seed: int = 0,
        on_led: LedListener | None = None,
        on_event: EventListener | None = None,
        timing: Timing = DEFAULT_TIMING,
    ) -> None:
        if rate <= 0:
            raise RoswireError(f"sim rate must be > 0 Hz, got {rate}")
        self.config = config
        self.typestore = typestore
        self.initial = robots
        self.prefix = prefix
        self.rate = rate
        self.domain_id = domain_id
        self.distro: Distro = distro
        self.seed = seed
        self.on_led = on_led
        self.on_event = on_event
        self.timing = timing
        self.published: Counter[str] = Counter()
        self.publish_errors = 0
        self._robots: dict[str, SimRobot] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._battery_every = max(1, round(rate))

    # --- lifecycle --------------------------------------------------------------------------

    def start(self) -> Fleet:
        """Start the initial robots and the thread that ticks them; returns self."""
        if self._thread is not None:
            return self
        self._stop.clear()
        for _ in range(self.initial):
            self.add_robot()
        self._thread = threading.Thread(target=self._run, name="sim-fleet", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the ticking thread and remove every robot."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None
        for name in self.names():
            self.remove_robot(name)

    def __enter__(self) -> Fleet:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    # --- robots -----------------------------------------------------------------------------

    def names(self) -> list[str]:
        """The names of the running robots, sorted."""
        with self._lock:
            return sorted(self._robots)

    def _next_name(self) -> str:
        index = 1
        while f"{self.prefix}{index:02d}" in self._robots:
            index += 1
        return f"{self.prefix}{index:02d}"

    def add_robot(self, name: str | None = None) -> str:
        """Start a robot called ``name`` (default: the first free ``<prefix>NN``); returns its name.

        Raises ``RoswireError`` when a robot of that name already runs.
        """
        with self._lock:
            name = name or self._next_name()
            if name in self._robots:
                raise RoswireError(f"robot {name} already runs")
            self._robots[name] = robot = self._make_robot(name)
        try:
            self._start_robot(robot)
        except Exception:
            with self._lock:
                self._robots.pop(name, None)
            robot.node.stop()
            raise
        log.info("robot %s started (zid %s)", name, robot.node.zid)
        return name

    def _make_robot(self, name: str) -> SimRobot:
        node = RosNode(
            "create3",
            f"/{name}",
            domain_id=self.domain_id,
            config=self.config,
            typestore=self.typestore,
            distro=self.distro,
        )
        return SimRobot(
            name, RobotModel(name, time.time(), self.seed), node, MessageFactory(self.typestore, name)
        )

    def _start_robot(self, robot: SimRobot) -> None:
        # under the robot's lock: the fleet's ticker must not see a started node without publishers
        with robot.lock:
            robot.node.start()
            for topic, (typename, qos) in TOPICS.items():
                robot.publishers[topic] = robot.node.create_publisher(topic, typename, qos)
        robot.node.create_subscriber(
            "cmd_lightring", LIGHTRING, lambda s: self._on_lightring(robot, s), decode=True
        )
        robot.services = RobotServices(
            robot.name,
            robot.node,
            robot.model,
            robot.lock,
            self.typestore,
            timing=self.timing,
            on_event=self.on_event,
        ).start()

    def remove_robot(self, name: str) -> None:
        """Stop a robot and its node; raises ``RoswireError`` when no robot has that name."""
        with self._lock:
            robot = self._robots.pop(name, None)
        if robot is None:
            raise RoswireError(f"no robot named {name}")
        with robot.lock:
            robot.stopped = True
        # outside the lock: undeclaring may wait for a light-ring callback that takes the lock
        robot.node.stop()
        log.info("robot %s stopped", name)

    def _get(self, name: str) -> SimRobot:
        with self._lock:
            robot = self._robots.get(name)
        if robot is None:
            raise RoswireError(f"no robot named {name}")
        return robot

    def inject_fault(self, name: str) -> None:
        """Pick the robot up: kidnap status true, IR readings high, wheels dropped."""
        robot = self._get(name)
        with robot.lock:
            robot.model.inject_fault()

    def heal(self, name: str) -> None:
        """Put a picked-up robot back on the floor (undoes :meth:`inject_fault`)."""
        robot = self._get(name)
        with robot.lock:
            robot.model.heal()

    def led(self, name: str) -> LedState:
        """What the robot's light ring shows now."""
        robot = self._get(name)
        with robot.lock:
            return robot.model.led

    def model(self, name: str) -> RobotModel:
        """The live model of a robot (unlocked: take the robot's lock to change it)."""
        return self._get(name).model

    def services(self, name: str) -> RobotServices | None:
        """The services and actions a robot serves (None before they are started)."""
        return self._get(name).services

    # --- running ----------------------------------------------------------------------------

    def _on_lightring(self, robot: SimRobot, sample: RosSample) -> None:
        colours = lightring_colours(sample.message)
        with robot.lock:
            state = robot.model.set_lightring(colours, bool(sample.message.override_system), time.time())
        log.info("robot %s light ring: %s", robot.name, state.name)
        if self.on_led is not None:
            self.on_led(robot.name, state)

    def _run(self) -> None:
        period = 1.0 / self.rate
        next_tick = time.monotonic()
        while not self._stop.is_set():
            with self._lock:
                robots = list(self._robots.values())
            for robot in robots:
                self._tick(robot, time.time())
            next_tick += period
            delay = next_tick - time.monotonic()
            if delay < 0:  # running late: skip ahead instead of bursting
                next_tick = time.monotonic()
                delay = 0
            self._stop.wait(delay)

    def _tick(self, robot: SimRobot, now: float) -> None:
        with robot.lock:
            if robot.stopped or not robot.node.started:
                return
            readings = robot.model.step(now)
            robot.ticks += 1
            f = robot.factory
            messages: dict[str, Any] = {
                "ir_intensity": f.ir_intensity(readings),
                "hazard_detection": f.hazard_detection(readings),
                "kidnap_status": f.kidnap_status(readings),
                "odom": f.odom(readings),
                "imu": f.imu(readings),
            }
            if robot.ticks % self._battery_every == 1 or self._battery_every == 1:
                messages["battery_state"] = f.battery_state(readings)
            for topic, msg in messages.items():
                try:
                    robot.publishers[topic].publish(msg)
                    self.published[topic] += 1
                except (RoswireError, zenoh.ZError) as exc:
                    self.publish_errors += 1
                    log.warning("robot %s: publishing %s failed: %s", robot.name, topic, exc)
