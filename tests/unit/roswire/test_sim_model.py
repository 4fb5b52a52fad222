"""The simulated robot's pure model and its messages."""

from __future__ import annotations

import math
from typing import Any

import pytest
from rosbags.typesys.store import Typestore

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
from fleetlink.roswire.sim.model import (
    ANGULAR_SPEED,
    HAZARD_WHEEL_DROP,
    IR_NORMAL_MAX,
    IR_PICKED_UP_MIN,
    IR_SENSORS,
    LINEAR_SPEED,
    LedState,
    RobotModel,
    colour_name,
)
from fleetlink.schemas.typestore import load_typestore
from tests.paths import IROBOT

CREATE3 = IROBOT


@pytest.fixture(scope="module")
def ts() -> Typestore:
    return load_typestore("jazzy", [CREATE3])


def test_healthy_robot_drives_a_circle_with_low_ir() -> None:
    model = RobotModel("tb4_01", start=1000.0)
    readings = [model.step(1000.0 + i * 0.1) for i in range(101)]
    last = readings[-1]
    assert not last.kidnapped
    assert last.hazards == ()
    assert all(0 <= v <= IR_NORMAL_MAX for r in readings for v in r.ir)
    assert len(last.ir) == len(IR_SENSORS)
    assert last.linear_velocity == LINEAR_SPEED
    assert last.yaw == pytest.approx(ANGULAR_SPEED * 10.0)
    travelled = math.hypot(last.x, last.y)
    assert 0.5 < travelled <= LINEAR_SPEED * 10.0


def test_picked_up_fault_and_heal() -> None:
    model = RobotModel("tb4_02", start=0.0)
    model.step(0.0)
    model.inject_fault()
    up = model.step(1.0)
    assert up.kidnapped
    assert min(up.ir) >= IR_PICKED_UP_MIN
    assert HAZARD_WHEEL_DROP in up.hazards
    assert (up.linear_velocity, up.angular_velocity) == (0.0, 0.0)
    x, y = model.x, model.y
    model.step(2.0)
    assert (model.x, model.y) == (x, y)  # standing still while held
    model.heal()
    down = model.step(3.0)
    assert not down.kidnapped
    assert max(down.ir) <= IR_NORMAL_MAX
    assert down.hazards == ()


def test_same_seed_same_noise() -> None:
    a, b = RobotModel("r", 0.0, seed=3), RobotModel("r", 0.0, seed=3)
    c = RobotModel("r", 0.0, seed=4)
    assert [a.step(t).ir for t in (0, 1)] == [b.step(t).ir for t in (0, 1)]
    assert a.step(2).ir != c.step(2).ir or a.step(3).ir != c.step(3).ir


def test_battery_drains_one_percent_per_minute() -> None:
    model = RobotModel("r", 0.0)
    model.step(0.0)
    assert model.step(60.0).battery_percentage == pytest.approx(0.99)


@pytest.mark.parametrize(
    ("colours", "override", "name"),
    [
        (((255, 0, 0),) * 6, True, "red"),
        (((0, 0, 0),) * 6, True, "off"),
        (((1, 2, 3),) * 6, True, "#010203"),
        (((255, 0, 0),) * 6, False, "green"),
        (((255, 0, 0),) * 3 + ((0, 0, 255),) * 3, True, "red,red,red,blue,blue,blue"),
    ],
)
def test_lightring(colours: tuple[tuple[int, int, int], ...], override: bool, name: str) -> None:
    model = RobotModel("r", 0.0)
    state = model.set_lightring(colours, override, 5.0)
    assert state.name == name
    assert model.led == state
    assert state.at == 5.0


def test_colour_names() -> None:
    assert colour_name((255, 255, 0)) == "yellow"
    assert LedState(((0, 255, 255),), True, 0).name == "cyan"


def test_messages_round_trip_through_cdr(ts: Typestore) -> None:
    model = RobotModel("tb4_01", 0.0)
    model.step(1700000000.0)
    model.inject_fault()
    r = model.step(1700000000.25)
    f = MessageFactory(ts, "tb4_01")
    for typename, msg in [
        (IR_VECTOR, f.ir_intensity(r)),
        (HAZARDS, f.hazard_detection(r)),
        (KIDNAP, f.kidnap_status(r)),
        (ODOMETRY, f.odom(r)),
        (IMU, f.imu(r)),
        (BATTERY, f.battery_state(r)),
    ]:
        raw = bytes(ts.serialize_cdr(msg, typename))
        back: Any = ts.deserialize_cdr(raw, typename)
        assert back.header.stamp.sec == 1700000000
        assert back.header.stamp.nanosec == 250_000_000
    ir: Any = ts.deserialize_cdr(bytes(ts.serialize_cdr(f.ir_intensity(r), IR_VECTOR)), IR_VECTOR)
    assert [x.value for x in ir.readings] == list(r.ir)
    assert [x.header.frame_id for x in ir.readings] == list(IR_SENSORS)
    assert f.kidnap_status(r).is_kidnapped is True
    assert [d.type for d in f.hazard_detection(r).detections] == list(r.hazards)
    cmd = f.lightring(((255, 0, 0),) * 6, True, 1.0)
    raw = bytes(ts.serialize_cdr(cmd, LIGHTRING))
    assert lightring_colours(ts.deserialize_cdr(raw, LIGHTRING)) == ((255, 0, 0),) * 6
