"""Robot registry: discovery, grace period, explicit registration (clock injected)."""

from __future__ import annotations

import pytest

from fleetlink.roswire.errors import RobotError
from fleetlink.roswire.graph import EventKind, Graph, GraphEvent
from fleetlink.roswire.qos import DEFAULT
from fleetlink.roswire.robots import Reason, RobotEventKind, RobotRegistry, RobotType, parse_registration
from fleetlink.roswire.tokens import EntityKind, endpoint_token, node_token

TYPES = [RobotType("turtlebot4", "/tb4_*"), RobotType("husky", "/husky?")]


def node(zid: str, ns: str, name: str = "sim") -> str:
    return node_token(0, zid, 0, ns, name)


def pub(zid: str, ns: str, topic: str, eid: int = 1) -> str:
    return endpoint_token(
        domain=0,
        zid=zid,
        nid=0,
        eid=eid,
        kind=EntityKind.PUBLISHER,
        namespace=ns,
        node_name="sim",
        topic=topic,
        typename="sensor_msgs/msg/Imu",
        type_hash="TypeHashNotSupported",
        qos=DEFAULT,
    )


class Harness:
    def __init__(self, grace: float = 2.0) -> None:
        self.graph = Graph()
        self.registry = RobotRegistry(TYPES, grace_s=grace)
        self.log: list[tuple[str, str, str, str, float]] = []

    def step(self, now: float, kind: str | None = None, key: str | None = None) -> None:
        events: list[GraphEvent] = self.graph.apply(kind, key) if kind and key else []
        out = []
        for ev in events:
            out.extend(self.registry.on_graph_event(ev, now))
        out.extend(self.registry.tick(now))
        self.log.extend((e.kind.value, e.robot, e.robot_type, e.reason.value, e.at) for e in out)


@pytest.mark.parametrize(
    ("ns", "expected"),
    [
        ("/tb4_07", ("tb4_07", "turtlebot4")),
        ("/tb4_07/sensors", ("tb4_07", "turtlebot4")),
        ("/husky1", ("husky1", "husky")),
        ("/husky12", None),
        ("/", None),
        ("/other", None),
        ("/x/tb4_07", None),
    ],
)
def test_classify(ns: str, expected: tuple[str, str] | None) -> None:
    assert RobotRegistry(TYPES).classify(ns) == expected


def test_robot_appears_with_first_entity_and_leaves_after_grace() -> None:
    h = Harness(grace=2.0)
    h.step(0.0, "put", node("a1", "/tb4_01"))
    h.step(0.1, "put", pub("a1", "/tb4_01", "/tb4_01/imu"))
    h.step(0.2, "put", node("b2", "/other"))
    h.step(1.0, "delete", pub("a1", "/tb4_01", "/tb4_01/imu"))
    h.step(1.5, "delete", node("a1", "/tb4_01"))
    h.step(3.4)  # 1.9 s after the last entity went: still registered
    assert "tb4_01" in h.registry
    h.step(3.5)
    assert h.log == [
        ("registered", "tb4_01", "turtlebot4", "discovered", 0.0),
        ("deregistered", "tb4_01", "turtlebot4", "liveliness_lost", 3.5),
    ]
    assert len(h.registry) == 0


def test_robot_back_within_grace_is_not_deregistered() -> None:
    h = Harness(grace=2.0)
    h.step(0.0, "put", node("a1", "/tb4_02"))
    h.step(1.0, "delete", node("a1", "/tb4_02"))
    h.step(2.0, "put", node("c3", "/tb4_02"))  # restarted with a new session
    h.step(10.0)
    assert [e[0] for e in h.log] == ["registered"]
    robot = h.registry.get("tb4_02")
    assert robot is not None
    assert robot.empty_since is None
    assert len(robot.entities) == 1


def test_zero_grace_deregisters_at_next_tick() -> None:
    h = Harness(grace=0.0)
    h.step(0.0, "put", node("a1", "/husky1"))
    h.step(0.5, "delete", node("a1", "/husky1"))
    assert h.log[-1] == ("deregistered", "husky1", "husky", "liveliness_lost", 0.5)


def test_explicit_registration_before_discovery() -> None:
    h = Harness(grace=1.0)
    events = h.registry.register("turtlebot4", "tb4_09", 0.0)
    assert [(e.kind, e.reason) for e in events] == [(RobotEventKind.REGISTERED, Reason.EXPLICIT)]
    h.step(100.0)
    assert "tb4_09" in h.registry  # never discovered: stays until deregistered or seen and lost
    h.step(101.0, "put", node("a1", "/tb4_09"))
    assert h.log == []  # already registered: discovery adds no event
    h.step(102.0, "delete", node("a1", "/tb4_09"))
    h.step(103.0)
    assert h.log == [("deregistered", "tb4_09", "turtlebot4", "liveliness_lost", 103.0)]


def test_explicit_registration_of_any_name_uses_its_type_for_classification() -> None:
    registry = RobotRegistry(TYPES)
    registry.register("husky", "field_bot", 0.0)
    assert registry.classify("/field_bot/nav") == ("field_bot", "husky")
    ev = GraphEvent(EventKind.APPEARED, Graph().put(node("a1", "/field_bot/nav"))[0].entity)
    assert registry.on_graph_event(ev, 1.0) == []
    robot = registry.get("field_bot")
    assert robot is not None
    assert robot.explicit
    assert len(robot.entities) == 1


def test_register_twice_and_deregister() -> None:
    registry = RobotRegistry(TYPES)
    assert len(registry.register("turtlebot4", "tb4_01", 0.0)) == 1
    assert registry.register("turtlebot4", "tb4_01", 1.0) == []
    (ev,) = registry.deregister("tb4_01", 2.0)
    assert (ev.kind, ev.reason, ev.at) == (RobotEventKind.DEREGISTERED, Reason.EXPLICIT, 2.0)
    assert registry.deregister("tb4_01", 3.0) == []


@pytest.mark.parametrize(
    ("robot_type", "name"),
    [("unknown", "tb4_01"), ("turtlebot4", "a/b"), ("turtlebot4", ""), ("turtlebot4", "1x")],
)
def test_register_rejects(robot_type: str, name: str) -> None:
    with pytest.raises(RobotError):
        RobotRegistry(TYPES).register(robot_type, name, 0.0)


@pytest.mark.parametrize(
    ("text", "parsed"), [("turtlebot4/tb4_07", ("turtlebot4", "tb4_07")), (" husky/h1\n", ("husky", "h1"))]
)
def test_parse_registration(text: str, parsed: tuple[str, str]) -> None:
    assert parse_registration(text) == parsed


@pytest.mark.parametrize("text", ["tb4_07", "/tb4_07", "turtlebot4/", "turtlebot4/a/b", ""])
def test_parse_registration_rejects(text: str) -> None:
    with pytest.raises(RobotError):
        parse_registration(text)


@pytest.mark.parametrize("pattern", ["tb4_*", "/a/b*", "/"])
def test_bad_patterns(pattern: str) -> None:
    with pytest.raises(RobotError):
        RobotType("x", pattern)


def test_negative_grace_rejected() -> None:
    with pytest.raises(RobotError):
        RobotRegistry(TYPES, grace_s=-1)
