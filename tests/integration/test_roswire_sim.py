"""The simulated TurtleBot 4 fleet on a real router: discovered as robots, publishes the Create 3
topics, shows the light-ring colour it is sent, and faults/robots can change at runtime."""

from __future__ import annotations

import itertools
import threading
from collections.abc import Iterator
from typing import Any

import pytest
from rosbags.typesys.store import Typestore

from fleetlink.roswire.node import RosNode
from fleetlink.roswire.qos import SENSOR_DATA
from fleetlink.roswire.robot_watcher import RobotWatcher
from fleetlink.roswire.robots import RobotEvent, RobotEventKind, RobotType
from fleetlink.roswire.sim.fleet import Fleet
from fleetlink.roswire.sim.messages import IR_VECTOR, KIDNAP, LIGHTRING, MessageFactory
from fleetlink.roswire.sim.model import IR_PICKED_UP_MIN, LedState
from fleetlink.roswire.subscriber import RosSample
from fleetlink.schemas.typestore import load_typestore
from tests.helpers import wait_until, zenoh_peer_config
from tests.paths import IROBOT

CREATE3 = IROBOT
_domains = itertools.count(401)


@pytest.fixture(scope="module")
def ts() -> Typestore:
    return load_typestore("jazzy", [CREATE3])


@pytest.fixture
def domain() -> int:
    return next(_domains)


@pytest.fixture
def operator(zenoh_router: str, domain: int, ts: Typestore) -> Iterator[RosNode]:
    with RosNode("operator", domain_id=domain, config=zenoh_peer_config(zenoh_router), typestore=ts) as n:
        yield n


def test_fleet_is_discovered_and_changes_at_runtime(
    zenoh_router: str, domain: int, ts: Typestore, operator: RosNode
) -> None:
    events: list[RobotEvent] = []
    with (
        RobotWatcher(
            operator,
            [RobotType("turtlebot4", "/tb4_*")],
            grace_s=0.2,
            tick_s=0.05,
            listeners=(events.append,),
        ) as watcher,
        Fleet(zenoh_peer_config(zenoh_router), ts, robots=2, rate=10, domain_id=domain) as fleet,
    ):
        wait_until(
            lambda: [r.name for r in watcher.robots()] == ["tb4_01", "tb4_02"],
            timeout=5,
            message="two simulated robots discovered",
        )
        graph = watcher.watcher
        assert graph is not None
        topics = graph.topics()
        for name, typename in [
            ("ir_intensity", IR_VECTOR),
            ("kidnap_status", KIDNAP),
            ("odom", "nav_msgs/msg/Odometry"),
            ("imu", "sensor_msgs/msg/Imu"),
            ("hazard_detection", "irobot_create_msgs/msg/HazardDetectionVector"),
            ("battery_state", "sensor_msgs/msg/BatteryState"),
        ]:
            assert topics[f"/tb4_01/{name}"].types == (typename,)
        assert topics["/tb4_01/cmd_lightring"].types == (LIGHTRING,)
        assert topics["/tb4_01/cmd_lightring"].subscribers
        assert topics["/tb4_01/imu"].publishers[0].qos == SENSOR_DATA
        added = fleet.add_robot()
        assert added == "tb4_03"
        wait_until(lambda: "tb4_03" in [r.name for r in watcher.robots()], timeout=2, message="added robot")
        fleet.remove_robot("tb4_01")
        wait_until(
            lambda: [r.name for r in watcher.robots()] == ["tb4_02", "tb4_03"],
            timeout=3,
            message="removed robot deregistered",
        )
        assert fleet.names() == ["tb4_02", "tb4_03"]
    kinds = [(e.robot, e.kind) for e in events]
    assert ("tb4_01", RobotEventKind.DEREGISTERED) in kinds
    assert kinds.count(("tb4_03", RobotEventKind.REGISTERED)) == 1


def test_picked_up_fault_shows_in_kidnap_and_ir_and_heals(
    zenoh_router: str, domain: int, ts: Typestore, operator: RosNode
) -> None:
    kidnap: list[bool] = []
    ir_max: list[int] = []
    lock = threading.Lock()

    def on_kidnap(s: RosSample) -> None:
        with lock:
            kidnap.append(bool(s.message.is_kidnapped))

    def on_ir(s: RosSample) -> None:
        with lock:
            ir_max.append(max(r.value for r in s.message.readings))

    operator.create_subscriber("/tb4_01/kidnap_status", KIDNAP, on_kidnap, decode=True)
    operator.create_subscriber("/tb4_01/ir_intensity", IR_VECTOR, on_ir, SENSOR_DATA, decode=True)
    with Fleet(zenoh_peer_config(zenoh_router), ts, robots=1, rate=20, domain_id=domain) as fleet:
        wait_until(lambda: len(kidnap) >= 3 and len(ir_max) >= 3, timeout=5, message="sensor data flowing")
        assert not any(kidnap)
        fleet.inject_fault("tb4_01")
        wait_until(lambda: kidnap[-1] and ir_max[-1] >= IR_PICKED_UP_MIN, timeout=3, message="picked up")
        fleet.heal("tb4_01")
        wait_until(lambda: not kidnap[-1] and ir_max[-1] < IR_PICKED_UP_MIN, timeout=3, message="healed")


def test_robot_shows_the_lightring_colour_it_is_sent(
    zenoh_router: str, domain: int, ts: Typestore, operator: RosNode
) -> None:
    shown: list[tuple[str, LedState]] = []
    with Fleet(
        zenoh_peer_config(zenoh_router),
        ts,
        robots=2,
        rate=10,
        domain_id=domain,
        on_led=lambda robot, state: shown.append((robot, state)),
    ) as fleet:
        assert fleet.led("tb4_02").name == "green"  # system colour before any command
        cmd = operator.create_publisher("/tb4_02/cmd_lightring", LIGHTRING)
        wait_until(lambda: cmd.matching, timeout=5, message="robot subscribed to cmd_lightring")
        factory = MessageFactory(ts, "operator")
        msg: Any = factory.lightring(((255, 0, 0),) * 6, True, 0.0)
        cmd.publish(msg)
        wait_until(lambda: fleet.led("tb4_02").name == "red", timeout=3, message="tb4_02 turns red")
        assert fleet.led("tb4_01").name == "green"
        cmd.publish(factory.lightring(((0, 0, 255),) * 6, False, 0.0))
        wait_until(lambda: fleet.led("tb4_02").name == "green", timeout=3, message="back to system colour")
        assert [(r, s.name) for r, s in shown] == [("tb4_02", "red"), ("tb4_02", "green")]
