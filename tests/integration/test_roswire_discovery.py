"""Graph discovery and the robot registry against a real zenoh router on loopback.

Every test uses its own ROS domain id, so tests sharing the session router never see each
other's tokens.
"""

from __future__ import annotations

import itertools
import json
import time
from collections.abc import Iterator

import pytest
import zenoh

from fleetlink.localstack.zenoh_router import ZenohRouter
from fleetlink.roswire import cdr
from fleetlink.roswire.discovery import GraphWatcher
from fleetlink.roswire.graph import EventKind, GraphEvent
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.qos import SENSOR_DATA, TRANSIENT_LOCAL
from fleetlink.roswire.robot_watcher import EVENTS_TOPIC, REGISTER_TOPIC, RobotWatcher
from fleetlink.roswire.robots import Reason, RobotEvent, RobotEventKind, RobotType
from fleetlink.roswire.subscriber import RosSample
from fleetlink.roswire.tokens import EndpointInfo, EntityKind, NodeInfo
from tests.helpers import free_port, wait_until, zenoh_peer_config

IMU = "sensor_msgs/msg/Imu"
IMU_HASH = "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b"
STRING = "std_msgs/msg/String"
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
TB4 = [RobotType("turtlebot4", "/tb4_*")]
_domains = itertools.count(101)


@pytest.fixture
def domain() -> int:
    return next(_domains)


@pytest.fixture
def observer(zenoh_router: str, domain: int) -> Iterator[RosNode]:
    with RosNode("fleetlink", domain_id=domain, config=zenoh_peer_config(zenoh_router)) as node:
        yield node


def robot(endpoint: str, domain: int, name: str) -> RosNode:
    """A simulated robot process: its own session, a node in /<name> and one publisher."""
    node = RosNode("sim", f"/{name}", domain_id=domain, config=zenoh_peer_config(endpoint)).start()
    node.create_publisher("imu", IMU, SENSOR_DATA, type_hash=IMU_HASH)
    return node


def test_robots_joining_and_leaving_are_seen_within_a_second(
    zenoh_router: str, domain: int, observer: RosNode
) -> None:
    events: list[tuple[RobotEvent, float]] = []
    with RobotWatcher(
        observer, TB4, grace_s=0.2, tick_s=0.05, listeners=(lambda e: events.append((e, time.monotonic())),)
    ):
        first = robot(zenoh_router, domain, "tb4_01")
        first_up = time.monotonic()  # its tokens are declared: from here discovery must take < 1 s
        second = robot(zenoh_router, domain, "tb4_02")
        second_up = time.monotonic()
        wait_until(lambda: len(events) == 2, timeout=5, message="two robots registered")
        seen = {e.robot: (e.kind, e.reason, t) for e, t in events}
        assert seen["tb4_01"][:2] == seen["tb4_02"][:2] == (RobotEventKind.REGISTERED, Reason.DISCOVERED)
        assert seen["tb4_01"][2] - first_up < 1.0
        assert seen["tb4_02"][2] - second_up < 1.0
        left = time.monotonic()
        first.stop()
        wait_until(lambda: len(events) == 3, timeout=5, message="tb4_01 deregistered")
        event, at = events[2]
        assert (event.robot, event.kind, event.reason) == (
            "tb4_01",
            RobotEventKind.DEREGISTERED,
            Reason.LIVELINESS_LOST,
        )
        assert at - left < 1.0
        second.stop()
        wait_until(lambda: len(events) == 4, timeout=5, message="tb4_02 deregistered")


def test_robot_running_before_discovery_starts_is_found(
    zenoh_router: str, domain: int, observer: RosNode
) -> None:
    early = robot(zenoh_router, domain, "tb4_07")
    try:
        with RobotWatcher(observer, TB4, grace_s=0.2) as watcher:
            # the node token and the publisher token (each token's reply comes on its own: the
            # robot is named at the first)
            wait_until(
                lambda: [(r.name, len(r.entities)) for r in watcher.robots()] == [("tb4_07", 2)],
                timeout=5,
                message="pre-existing robot tb4_07 found with its node and its publisher",
            )
            (found,) = watcher.robots()
            assert found.robot_type == "turtlebot4"
    finally:
        early.stop()


def test_graph_shows_nodes_topics_types_and_qos(zenoh_router: str, domain: int, observer: RosNode) -> None:
    events: list[GraphEvent] = []
    with GraphWatcher(observer.session, domain, listeners=(events.append,)) as watcher:
        node = RosNode("tf_pub", "/tb4_03", domain_id=domain, config=zenoh_peer_config(zenoh_router)).start()
        try:
            node.create_publisher(
                "/tf_static", "tf2_msgs/msg/TFMessage", TRANSIENT_LOCAL, type_hash="TypeHashNotSupported"
            )
            node.create_subscriber(
                "cmd_vel", "geometry_msgs/msg/Twist", lambda s: None, type_hash="TypeHashNotSupported"
            )
            wait_until(lambda: len(watcher.topics()) == 2, timeout=5, message="two topics")
            topics = watcher.topics()
            tf = topics["/tf_static"]
            assert tf.types == ("tf2_msgs/msg/TFMessage",)
            assert [p.qos for p in tf.publishers] == [TRANSIENT_LOCAL]
            assert tf.publishers[0].zid == node.zid
            cmd = topics["/tb4_03/cmd_vel"]
            assert [s.kind for s in cmd.subscribers] == [EntityKind.SUBSCRIPTION]
            assert [n.fqn for n in watcher.nodes()] == ["/tb4_03/tf_pub"]
            assert all(e.kind is EventKind.APPEARED for e in events)
        finally:
            node.stop()
        wait_until(lambda: len(watcher) == 0, timeout=5, message="all tokens gone after stop")
        gone = [e.entity for e in events if e.kind is EventKind.DISAPPEARED]
        assert sum(isinstance(e, EndpointInfo) for e in gone) == 2
        assert sum(isinstance(e, NodeInfo) for e in gone) == 1
        # the observer's own node token is never part of the graph
        assert all(e.entity.zid != observer.zid for e in events)


def test_malformed_tokens_are_counted_and_never_stop_discovery(
    zenoh_router: str, domain: int, observer: RosNode
) -> None:
    bad_keys = [
        f"@ros2_lv/{domain}/zz/0/0/NN/%/%/x",  # zid not hex
        f"@ros2_lv/{domain}/ab/0/0/NN/%/%",  # too few chunks
        f"@ros2_lv/{domain}/ab/0/1/MP/%/%/n/%t/not_a_type/TypeHashNotSupported/::,10:,:,:,,",
        f"@ros2_lv/{domain}/ab/0/1/MP/%/%/n/%t/std_msgs::msg::dds_::String_/TypeHashNotSupported/garbage",
        f"@ros2_lv/{domain}/ab/0/0/QQ/%/%/n",  # unknown kind
    ]
    with zenoh.open(zenoh_peer_config(zenoh_router)) as vandal:
        tokens = [vandal.liveliness().declare_token(k) for k in bad_keys]
        with GraphWatcher(observer.session, domain) as watcher:
            wait_until(
                lambda: watcher.stats.malformed == len(bad_keys),
                timeout=5,
                message="every malformed token counted",
            )
            good = robot(zenoh_router, domain, "tb4_05")
            try:
                wait_until(
                    lambda: "/tb4_05/imu" in watcher.topics(),
                    timeout=5,
                    message="discovery continues after malformed tokens",
                )
                for token in tokens:
                    token.undeclare()
                wait_until(
                    lambda: watcher.stats.deletes >= len(bad_keys),
                    timeout=5,
                    message="deletes of malformed tokens seen",
                )
                assert [n.fqn for n in watcher.nodes()] == ["/tb4_05/sim"]
                assert watcher.stats.malformed == len(bad_keys)
            finally:
                good.stop()


def test_explicit_registration_topic_and_robot_events_topic(
    zenoh_router: str, domain: int, observer: RosNode
) -> None:
    published: list[dict[str, str]] = []
    with RosNode("ops", domain_id=domain, config=zenoh_peer_config(zenoh_router)) as ops:
        ops.create_subscriber(
            EVENTS_TOPIC,
            STRING,
            lambda s: published.append(json.loads(cdr.decode_string(s.payload))),
            type_hash=STRING_HASH,
        )
        register = ops.create_publisher(REGISTER_TOPIC, STRING, type_hash=STRING_HASH)
        with RobotWatcher(
            observer, TB4, grace_s=0.2, tick_s=0.05, registrations=True, events_topic=EVENTS_TOPIC
        ) as watcher:
            wait_until(lambda: register.matching, timeout=5, message="watcher listens on /fleetlink/register")
            register.publish_cdr(cdr.encode_string("turtlebot4/tb4_42"))  # not running yet
            register.publish_cdr(cdr.encode_string("forklift/fl_1"))  # unknown type: ignored
            register.publish_cdr(b"\x00\x01\x00\x00garbage")  # not a String: ignored
            wait_until(
                lambda: [r.name for r in watcher.robots()] == ["tb4_42"],
                timeout=5,
                message="explicitly registered robot",
            )
            assert watcher.robots()[0].explicit
            wait_until(lambda: watcher.bad_registrations == 2, timeout=5, message="bad registrations counted")
            late = robot(zenoh_router, domain, "tb4_42")
            wait_until(lambda: len(watcher.robots()[0].entities) == 2, timeout=5, message="robot shows up")
            late.stop()
            wait_until(lambda: not watcher.robots(), timeout=5, message="deregistered when it leaves")
            wait_until(lambda: len(published) == 2, timeout=5, message="two events on the events topic")
    assert published == [
        {"event": "registered", "robot": "tb4_42", "robot_type": "turtlebot4", "reason": "explicit"},
        {"event": "deregistered", "robot": "tb4_42", "robot_type": "turtlebot4", "reason": "liveliness_lost"},
    ]


def test_router_restart_discovery_and_subscription_come_back(domain: int) -> None:
    """Reliability matrix #13: sessions reconnect by themselves; a restart shorter than the grace
    period does not deregister robots."""
    port = free_port()
    router = ZenohRouter(port).start()
    events: list[RobotEvent] = []
    samples: list[RosSample] = []
    try:
        with (
            RosNode(
                "fleetlink", domain_id=domain, config=zenoh_peer_config(router.endpoint, "client")
            ) as obs,
            RosNode(
                "sim", "/tb4_09", domain_id=domain, config=zenoh_peer_config(router.endpoint, "client")
            ) as bot,
        ):
            obs.create_subscriber("/tb4_09/imu", IMU, samples.append, type_hash=IMU_HASH)
            pub = bot.create_publisher("imu", IMU, SENSOR_DATA, type_hash=IMU_HASH)
            with RobotWatcher(obs, TB4, grace_s=10.0, listeners=(events.append,)) as watcher:
                graph = watcher.watcher
                assert graph is not None
                wait_until(lambda: len(graph) == 2, timeout=5, message="robot node and publisher seen")
                wait_until(lambda: pub.matching, timeout=5, message="subscriber matched")
                pub.publish_cdr(b"\x00\x01\x00\x00")
                wait_until(lambda: len(samples) == 1, timeout=5, message="first sample")
                router.stop()
                wait_until(lambda: len(graph) == 0, timeout=5, message="tokens gone with the router")
                router = ZenohRouter(port).start()
                wait_until(lambda: len(graph) == 2, timeout=15, message="tokens back after reconnect")
                wait_until(lambda: pub.matching, timeout=15, message="subscription back after reconnect")
                pub.publish_cdr(b"\x00\x01\x00\x00")
                wait_until(lambda: len(samples) == 2, timeout=5, message="sample after the restart")
                assert [r.name for r in watcher.robots()] == ["tb4_09"]
    finally:
        router.stop()
    assert [(e.robot, e.kind) for e in events] == [("tb4_09", RobotEventKind.REGISTERED)]
    assert samples[1].seq == 2
