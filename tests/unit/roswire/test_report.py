"""The `ros graph` report: rates from data keys, JSON shape, text rendering."""

from __future__ import annotations

import json

import pytest

from fleetlink.roswire.graph import Graph
from fleetlink.roswire.qos import SENSOR_DATA
from fleetlink.roswire.report import RateMeter, graph_report, render_text
from fleetlink.roswire.robots import RobotRegistry, RobotType
from fleetlink.roswire.tokens import EntityKind, endpoint_token, node_token

IMU_HASH = "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b"
KEYS = [
    node_token(0, "ab", 0, "/tb4_01", "create3"),
    endpoint_token(
        domain=0,
        zid="ab",
        nid=0,
        eid=1,
        kind=EntityKind.PUBLISHER,
        namespace="/tb4_01",
        node_name="create3",
        topic="/tb4_01/imu",
        typename="sensor_msgs/msg/Imu",
        type_hash=IMU_HASH,
        qos=SENSOR_DATA,
    ),
    endpoint_token(
        domain=0,
        zid="cd",
        nid=0,
        eid=2,
        kind=EntityKind.SERVICE_SERVER,
        namespace="/",
        node_name="srv",
        topic="/add",
        typename="example_interfaces/srv/AddTwoInts",
        type_hash="TypeHashNotSupported",
        qos=SENSOR_DATA,
    ),
]


def test_rate_meter_counts_topics_and_unparsed_keys() -> None:
    meter = RateMeter()
    key = f"0/tb4_01/imu/sensor_msgs::msg::dds_::Imu_/{IMU_HASH}"
    for _ in range(20):
        meter.on_key(key)
    meter.on_key("0/garbage")
    assert meter.rates(2.0) == {"/tb4_01/imu": 10.0}
    assert meter.unparsed == 1
    assert meter.rates(0.0) == {}
    meter.reset()
    assert meter.rates(1.0) == {}


@pytest.fixture
def world() -> tuple[Graph, RobotRegistry]:
    graph = Graph()
    registry = RobotRegistry([RobotType("turtlebot4", "/tb4_*")])
    for key in KEYS:
        for event in graph.put(key):
            registry.on_graph_event(event, 0.0)
    return graph, registry


def test_report_json_and_text(world: tuple[Graph, RobotRegistry]) -> None:
    graph, registry = world
    report = graph_report(
        domain_id=3,
        robots=registry.robots(),
        nodes=graph.nodes(),
        topics=graph.topics(),
        services=graph.services(),
        rates={"/tb4_01/imu": 9.996},
        malformed_tokens=2,
    )
    assert json.loads(json.dumps(report)) == report
    assert report["robots"] == [{"name": "tb4_01", "type": "turtlebot4", "entities": 2, "explicit": False}]
    (imu,) = report["topics"]
    assert imu["rate_hz"] == 10.0
    assert imu["publishers"][0]["qos"] == "best_effort, volatile, keep_last 5"
    assert imu["publishers"][0]["qos_wire"] == "2::,5:,:,:,,"
    assert imu["publishers"][0]["node"] == "/tb4_01/create3"
    assert len(imu["publishers"][0]["gid"]) == 32
    assert report["services"][0]["servers"][0]["type"] == "example_interfaces/srv/AddTwoInts"
    text = render_text(report)
    assert "tb4_01           type=turtlebot4 entities=2" in text
    assert "10.0 Hz" in text
    assert "[best_effort, volatile, keep_last 5]" in text
    assert "2::,5" not in text  # the wire encoding stays in the JSON
    assert "servers=1 clients=0" in text
    assert "malformed liveliness tokens ignored: 2" in text


def test_report_without_rates_has_no_rate_field(world: tuple[Graph, RobotRegistry]) -> None:
    graph, _ = world
    report = graph_report(
        domain_id=0, robots=[], nodes=graph.nodes(), topics=graph.topics(), services={}, rates=None
    )
    assert "rate_hz" not in report["topics"][0]
    assert "Hz" not in render_text(report)
    assert "malformed" not in render_text(report)
