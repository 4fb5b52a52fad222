"""Graph state from token PUT/DELETE sequences."""

from __future__ import annotations

import pytest

from fleetlink.roswire.errors import TokenError
from fleetlink.roswire.graph import EventKind, Graph
from fleetlink.roswire.qos import DEFAULT, SENSOR_DATA, QoS
from fleetlink.roswire.tokens import EndpointInfo, EntityKind, NodeInfo, endpoint_token, node_token

H = "TypeHashNotSupported"


def nn(zid: str, nid: int, ns: str, name: str) -> str:
    return node_token(0, zid, nid, ns, name)


def ep(
    zid: str,
    nid: int,
    eid: int,
    kind: EntityKind,
    ns: str,
    node: str,
    topic: str,
    typename: str = "std_msgs/msg/String",
    qos: QoS = DEFAULT,
) -> str:
    return endpoint_token(
        domain=0,
        zid=zid,
        nid=nid,
        eid=eid,
        kind=kind,
        namespace=ns,
        node_name=node,
        topic=topic,
        typename=typename,
        type_hash=H,
        qos=qos,
    )


TALKER = nn("a1", 0, "/", "talker")
TALKER_PUB = ep("a1", 0, 1, EntityKind.PUBLISHER, "/", "talker", "/chatter")
LISTENER_SUB = ep("b2", 0, 1, EntityKind.SUBSCRIPTION, "/", "listener", "/chatter")
IMU_PUB = ep(
    "c3", 2, 7, EntityKind.PUBLISHER, "/tb4_01", "sim", "/tb4_01/imu", "sensor_msgs/msg/Imu", SENSOR_DATA
)
ADD = "example_interfaces/srv/AddTwoInts"
SERVER = ep("a1", 0, 2, EntityKind.SERVICE_SERVER, "/", "talker", "/add", ADD)
CLIENT = ep("b2", 0, 3, EntityKind.SERVICE_CLIENT, "/", "listener", "/add", ADD)


def summary(events: list) -> list[tuple[str, str, str]]:  # type: ignore[type-arg]
    out = []
    for e in events:
        ent = e.entity
        what = "NN" if isinstance(ent, NodeInfo) else ent.kind.value
        name = ent.fqn if isinstance(ent, NodeInfo) else ent.topic
        out.append((e.kind.value, what, name))
    return out


SEQUENCES: list[tuple[str, list[tuple[str, str]], list[tuple[str, str, str]]]] = [
    (
        "node token then endpoint",
        [("put", TALKER), ("put", TALKER_PUB)],
        [("appeared", "NN", "/talker"), ("appeared", "MP", "/chatter")],
    ),
    (
        "endpoint creates node implicitly",
        [("put", LISTENER_SUB)],
        [("appeared", "NN", "/listener"), ("appeared", "MS", "/chatter")],
    ),
    ("duplicate put is silent", [("put", TALKER), ("put", TALKER)], [("appeared", "NN", "/talker")]),
    ("delete unknown is silent", [("delete", TALKER_PUB)], []),
    (
        "last endpoint of implicit node removes it",
        [("put", LISTENER_SUB), ("delete", LISTENER_SUB)],
        [
            ("appeared", "NN", "/listener"),
            ("appeared", "MS", "/chatter"),
            ("disappeared", "MS", "/chatter"),
            ("disappeared", "NN", "/listener"),
        ],
    ),
    (
        "node stays while its token lives",
        [("put", TALKER), ("put", TALKER_PUB), ("delete", TALKER_PUB)],
        [("appeared", "NN", "/talker"), ("appeared", "MP", "/chatter"), ("disappeared", "MP", "/chatter")],
    ),
    (
        "node stays while endpoints live",
        [("put", TALKER), ("put", TALKER_PUB), ("delete", TALKER)],
        [("appeared", "NN", "/talker"), ("appeared", "MP", "/chatter")],
    ),
    (
        "node goes with its last token",
        [("put", TALKER), ("put", TALKER_PUB), ("delete", TALKER), ("delete", TALKER_PUB)],
        [
            ("appeared", "NN", "/talker"),
            ("appeared", "MP", "/chatter"),
            ("disappeared", "MP", "/chatter"),
            ("disappeared", "NN", "/talker"),
        ],
    ),
]


@pytest.mark.parametrize(("label", "steps", "expected"), SEQUENCES, ids=[s[0] for s in SEQUENCES])
def test_event_sequences(
    label: str, steps: list[tuple[str, str]], expected: list[tuple[str, str, str]]
) -> None:
    graph = Graph()
    events = []
    for kind, key in steps:
        events.extend(graph.apply(kind, key))
    assert summary(events) == expected, label


def test_topics_services_and_namespaces() -> None:
    graph = Graph()
    for key in (TALKER, TALKER_PUB, LISTENER_SUB, IMU_PUB, SERVER, CLIENT):
        graph.put(key)
    topics = graph.topics()
    assert list(topics) == ["/chatter", "/tb4_01/imu"]
    chatter = topics["/chatter"]
    assert chatter.types == ("std_msgs/msg/String",)
    assert [p.node_name for p in chatter.publishers] == ["talker"]
    assert [s.node_name for s in chatter.subscribers] == ["listener"]
    assert topics["/tb4_01/imu"].publishers[0].qos == SENSOR_DATA
    services = graph.services()
    assert list(services) == ["/add"]
    assert services["/add"].types == ("example_interfaces/srv/AddTwoInts",)
    assert [s.kind for s in services["/add"].publishers] == [EntityKind.SERVICE_SERVER]
    assert [c.kind for c in services["/add"].subscribers] == [EntityKind.SERVICE_CLIENT]
    assert [n.fqn for n in graph.nodes()] == ["/listener", "/talker", "/tb4_01/sim"]
    assert [e.key for e in graph.in_namespace("/tb4_01")] == [IMU_PUB]
    assert len(graph.in_namespace("/")) == 6
    assert [e.eid for e in graph.node_endpoints(("a1", 0))] == [1, 2]
    assert len(graph) == 6
    assert TALKER in graph


def test_two_types_on_one_topic() -> None:
    graph = Graph()
    graph.put(TALKER_PUB)
    graph.put(ep("d4", 0, 1, EntityKind.PUBLISHER, "/", "other", "/chatter", "std_msgs/msg/Int32"))
    assert graph.topics()["/chatter"].types == ("std_msgs/msg/Int32", "std_msgs/msg/String")


def test_own_session_and_other_domains_ignored() -> None:
    graph = Graph(own_zid="a1", domain=0)
    assert graph.put(TALKER) == []
    assert graph.put(TALKER_PUB) == []
    assert graph.put(node_token(5, "b2", 0, "/", "far")) == []
    assert graph.ignored == 3
    assert graph.delete(TALKER) == []
    assert [e.kind for e in graph.put(LISTENER_SUB)] == [EventKind.APPEARED, EventKind.APPEARED]


def test_malformed_put_raises_and_leaves_state_intact() -> None:
    graph = Graph()
    graph.put(TALKER)
    with pytest.raises(TokenError):
        graph.put("@ros2_lv/0/a1/0/0/NN/%/%")
    with pytest.raises(ValueError, match="put"):
        graph.apply("upsert", TALKER)
    assert [n.fqn for n in graph.nodes()] == ["/talker"]


def test_drop_session() -> None:
    graph = Graph()
    for key in (TALKER, TALKER_PUB, SERVER, LISTENER_SUB):
        graph.put(key)
    events = graph.drop_session("a1")
    assert sorted(summary(events)) == sorted(
        [("disappeared", "MP", "/chatter"), ("disappeared", "SS", "/add"), ("disappeared", "NN", "/talker")]
    )
    assert [n.fqn for n in graph.nodes()] == ["/listener"]


def test_endpoint_info_fields() -> None:
    graph = Graph()
    (node_ev, ep_ev) = graph.put(IMU_PUB)
    assert isinstance(node_ev.entity, NodeInfo)
    assert node_ev.entity.fqn == "/tb4_01/sim"
    assert node_ev.entity.key == nn("c3", 2, "/tb4_01", "sim")
    assert isinstance(ep_ev.entity, EndpointInfo)
    assert ep_ev.entity.node_fqn == "/tb4_01/sim"
