"""fleetlink.console.graph: robots -> ROS topics -> mappings -> Kafka topics, with rates."""

from __future__ import annotations

from typing import Any

from fleetlink.console.graph import SITE_LEVEL, build_graph

ROBOTS = [
    {"robot": "tb4_01", "robot_type": "tb4", "state": "registered"},
    {"robot": "tb4_02", "robot_type": "tb4", "state": "lost"},
]
PUB = [{"node": "/tb4_01/create3", "type": "t", "type_hash": "h"}]


def topic(name: str, *matches: tuple[str, str | None, str], publishers: bool = True) -> dict[str, Any]:
    return {
        "topic": name,
        "types": ["pkg/msg/T"],
        "publishers": PUB if publishers else [],
        "subscribers": 0,
        "mappings": [{"mapping": m, "robot": r, "kafka_topic": k, "key": r or "k"} for m, r, k in matches],
    }


def mapping(name: str, to: str, robot_type: str | None = "tb4", issues: bool = False) -> dict[str, Any]:
    return {
        "name": name,
        "robot_type": robot_type,
        "to": to,
        "issues": [{"reason": "unknown_type", "detail": "x"}] if issues else [],
    }


def ids(nodes: list[dict[str, Any]]) -> list[str]:
    return [n["id"] for n in nodes]


def test_columns_edges_and_rates() -> None:
    topics = [
        topic("/tb4_01/ir", ("ir", "tb4_01", "fleet.ir")),
        topic("/tb4_02/ir", ("ir", "tb4_02", "fleet.ir")),
        topic("/tb4_01/imu", ("imu", "tb4_01", "fleet.tb4_01.imu")),
        topic("/tb4_02/imu", ("imu", "tb4_02", "fleet.tb4_02.imu")),
        topic("/tb4_01/odom"),  # discovered, not mapped
        topic("/kb_01/scan"),  # a namespace no robot type took (or another site's robot): counted
        topic("/kb_01/odom"),
        topic("/gps/fix", ("gps", None, "fleet.gps")),  # a site-level mapping
        topic("/tb4_01/cmd", publishers=False),  # subscribed only: not shown
        topic("/fleetlink/register"),  # fleetlink's own: never a robot
        topic("/fleetlink/robots"),
    ]
    mappings = [
        mapping("ir", "fleet.ir"),
        mapping("imu", "fleet.{robot}.imu", issues=True),
        mapping("gps", "fleet.gps", robot_type=None),
        mapping("idle", "fleet.idle"),
    ]
    graph = build_graph(
        ROBOTS,
        topics,
        mappings,
        topic_rates={"/tb4_01/ir": 10.0, "/tb4_02/ir": 12.0, "/tb4_01/imu": 50.0, "/gps/fix": None},
        mapping_rates={
            "ir": {"received": 22.0, "emitted": 4.0, "dropped": 18.0, "dead_lettered": 0.0},
            "imu": {"received": 100.0, "emitted": 100.0, "dropped": 0.0},
        },
        kafka_rates={"fleet.ir": 3.0, "fleet.tb4_01.imu": 40.0},
        backlog={"records": 12, "bytes": 1000, "oldest_age_s": 2.0},
    )
    assert ids(graph["robots"]) == ["r:tb4_01", "r:tb4_02", f"r:{SITE_LEVEL}"]
    assert [n["state"] for n in graph["robots"]] == ["registered", "lost", "site"]
    assert graph["elsewhere"] == {"kb_01": 2}
    assert graph["backlog"] == {"records": 12, "bytes": 1000, "oldest_age_s": 2.0}
    assert graph["kafka_reported"]
    # topics grouped by robot, in the robots' order
    assert ids(graph["topics"]) == [
        "t:/tb4_01/imu",
        "t:/tb4_01/ir",
        "t:/tb4_01/odom",
        "t:/tb4_02/imu",
        "t:/tb4_02/ir",
        "t:/gps/fix",
    ]
    by_id = {n["id"]: n for n in graph["topics"]}
    assert (by_id["t:/tb4_01/ir"]["rate"], by_id["t:/tb4_01/ir"]["mapped"]) == (10.0, True)
    assert (by_id["t:/tb4_01/odom"]["rate"], by_id["t:/tb4_01/odom"]["mapped"]) == (None, False)
    nodes = {n["id"]: n for n in graph["mappings"]}
    assert (nodes["m:ir"]["in"], nodes["m:ir"]["out"], nodes["m:ir"]["drop"], nodes["m:ir"]["topics"]) == (
        22.0,
        4.0,
        18.0,
        2,
    )
    assert nodes["m:imu"]["degraded"]
    assert not nodes["m:ir"]["degraded"]
    assert nodes["m:gps"]["detail"] == "site mapping"
    assert nodes["m:idle"]["in"] is None
    # the Kafka column: what Kafka acknowledged; what the mappings put out beside it
    kafka = {n["id"]: (n["rate"], n["mapped"], n["approx"]) for n in graph["kafka"]}
    assert kafka == {
        "k:fleet.ir": (3.0, 4.0, False),
        "k:fleet.tb4_01.imu": (40.0, 50.0, True),
        "k:fleet.tb4_02.imu": (0.0, 50.0, True),  # mapped, nothing acknowledged
        "k:fleet.gps": (0.0, None, False),
        "k:fleet.idle": (0.0, None, False),
    }  # an idle mapping still shows where it writes
    edges = {(e["from"], e["to"]): e["rate"] for e in graph["edges"]}
    assert edges[("r:tb4_01", "t:/tb4_01/ir")] == 10.0
    assert edges[("t:/tb4_02/ir", "m:ir")] == 12.0
    assert edges[("m:ir", "k:fleet.ir")] == 3.0  # the acknowledged rate, not the mapping's output
    assert edges[("m:imu", "k:fleet.tb4_02.imu")] == 0.0
    assert edges[(f"r:{SITE_LEVEL}", "t:/gps/fix")] is None
    assert not any("kb_01" in e["from"] or "fleetlink" in e["to"] for e in graph["edges"])
    assert ("m:idle", "k:fleet.idle") in edges
    assert not any(e["to"] == "t:/tb4_01/cmd" for e in graph["edges"])


def test_a_robot_named_by_a_mapping_but_not_registered() -> None:
    graph = build_graph(
        [],
        [topic("/tb4_09/ir", ("battery", "tb4_09", "fleet.battery"))],
        [mapping("battery", "fleet.battery", robot_type=None)],
        topic_rates={},
        mapping_rates={},
    )
    assert [(n["id"], n["state"], n["detail"]) for n in graph["robots"]] == [
        ("r:tb4_09", "unregistered", "not registered here")
    ]  # its topic is mapped here: the data flows through this site, so it is shown


def test_without_delivery_figures_the_kafka_column_says_so() -> None:
    graph = build_graph(
        ROBOTS,
        [topic("/tb4_01/ir", ("ir", "tb4_01", "fleet.ir"))],
        [mapping("ir", "fleet.ir")],
        topic_rates={},
        mapping_rates={"ir": {"emitted": 5.0}},
    )
    assert not graph["kafka_reported"]
    assert [(n["rate"], n["mapped"]) for n in graph["kafka"]] == [(None, 5.0)]


def test_two_mappings_share_what_kafka_acknowledged_in_proportion() -> None:
    graph = build_graph(
        ROBOTS,
        [topic("/tb4_01/a", ("a", "tb4_01", "fleet.x")), topic("/tb4_01/b", ("b", "tb4_01", "fleet.x"))],
        [mapping("a", "fleet.x"), mapping("b", "fleet.x")],
        topic_rates={},
        mapping_rates={"a": {"emitted": 3.0}, "b": {"emitted": 1.0}},
        kafka_rates={"fleet.x": 2.0},
    )
    edges = {(e["from"], e["to"]): e["rate"] for e in graph["edges"]}
    assert edges[("m:a", "k:fleet.x")] == 1.5
    assert edges[("m:b", "k:fleet.x")] == 0.5


def test_an_empty_site() -> None:
    assert build_graph([], [], [], topic_rates={}, mapping_rates={}) == {
        "robots": [],
        "topics": [],
        "mappings": [],
        "kafka": [],
        "edges": [],
        "elsewhere": {},
        "backlog": None,
        "kafka_reported": False,
    }
