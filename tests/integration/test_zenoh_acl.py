"""Zenoh ACL scoping of sites (reliability row 28), with the shipped router templates.

A fleet on loopback: the cloud router (deploy/zenoh/cloud-router.json5, mTLS, per-site ACL),
one edge router per site (deploy/zenoh/edge-router.json5) connected to it over TLS with its
``edge-<site>`` certificate, an uplink client (``fleetlink-uplink`` certificate) subscribed to
``fleetlink/**`` with a queryable on ``fleetlink/*/ingest/*``, and robot/agent clients on each
site network (plain TCP to their edge router).

Absence is checked behind a sentinel: a forbidden message is sent first, an allowed one after
it on the same session and path; once the allowed one has arrived, the forbidden one would
have arrived too, had it been let through (zenoh keeps order per link and priority).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import zenoh

from fleetlink.common.certs import CertBundle
from fleetlink.common.zenoh_configs import render_router_config
from tests.helpers import free_port, wait_until
from tests.integration.zenoh_topology import (
    DEPLOY,
    Collector,
    client_config,
    edge_identity_config,
    make_bundle,
    opened,
    routers_connected,
    tls_cloud,
    tls_edge,
    uplink_config,
)

_seq = itertools.count()


@dataclass
class Fleet:
    bundle: CertBundle
    cloud: zenoh.Session
    uplink: zenoh.Session
    robot_a: zenoh.Session  # a client on site A's network (robot or edge agent)
    robot_b: zenoh.Session  # a client on site B's network
    at_cloud: Collector  # uplink subscriber on fleetlink/**
    at_cloud_a: Collector  # uplink subscriber on fleetlink/site-a/**
    at_site_a: Collector  # subscriber on fleetlink/site-a/** on site A's network
    cloud_endpoint: str


def ingest_ack(query: zenoh.Query) -> None:
    query.reply(query.key_expr, b"ack")


def admin_replier(site: str) -> Callable[[zenoh.Query], None]:
    """An admin queryable answering on its concrete key (a reply that echoed a wildcard query
    key such as fleetlink/*/admin/robots would not be within the site's keys, and is dropped)."""

    def reply(query: zenoh.Query) -> None:
        query.reply(f"fleetlink/{site}/admin/robots", f"admin-{site[-1]}".encode())

    return reply


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Fleet]:
    bundle = make_bundle(tmp_path_factory.mktemp("certs"))
    with (
        tls_cloud(bundle) as cloud,
        tls_edge(bundle, "site-a", cloud.endpoint) as edge_a,
        tls_edge(bundle, "site-b", cloud.endpoint) as edge_b,
        opened(uplink_config(bundle, cloud.endpoint)) as uplink,
        opened(client_config(edge_a.endpoint)) as robot_a,
        opened(client_config(edge_b.endpoint)) as robot_b,
    ):
        assert routers_connected(edge_a.session) == 1
        assert routers_connected(edge_b.session) == 1
        at_cloud, at_cloud_a, at_site_a = Collector(), Collector(), Collector()
        # Kept referenced for the module; closing the sessions undeclares them.
        entities = [
            uplink.declare_subscriber("fleetlink/**", at_cloud),
            uplink.declare_subscriber("fleetlink/site-a/**", at_cloud_a),
            robot_a.declare_subscriber("fleetlink/site-a/**", at_site_a),
            uplink.declare_queryable("fleetlink/*/ingest/*", ingest_ack),
            robot_a.declare_queryable("fleetlink/site-a/admin/**", admin_replier("site-a")),
            robot_b.declare_queryable("fleetlink/site-b/admin/**", admin_replier("site-b")),
        ]
        fleet = Fleet(
            bundle, cloud.session, uplink, robot_a, robot_b, at_cloud, at_cloud_a, at_site_a, cloud.endpoint
        )
        # Routes are in place once site A's data reaches the cloud.
        wait_until(
            lambda: _put_seen(fleet.robot_a, "fleetlink/site-a/events/warm-up", at_cloud),
            10,
            message="site A -> cloud route",
        )
        yield fleet
        del entities


def _put_seen(session: zenoh.Session, key: str, collector: Collector) -> bool:
    session.put(key, b"probe")
    return key in set(collector.key_exprs())


def _unique(prefix: str) -> str:
    return f"{prefix}-{next(_seq)}"


def _payloads(collector: Collector) -> set[bytes]:
    return {payload for _, payload in collector.items}


def _replies(session: zenoh.Session, selector: str) -> list[tuple[str, bytes]]:
    out = []
    for reply in session.get(selector, timeout=3.0):
        if reply.ok is not None:
            out.append((str(reply.ok.key_expr), reply.ok.payload.to_bytes()))
    return out


def _attack_then_sentinel(attacker: zenoh.Session, fleet: Fleet, own_site: str) -> bytes:
    """Put forbidden samples into site A's keys, then allowed ones on the attacker's own site."""
    forbidden = _unique("forbidden").encode()
    sentinel = _unique("sentinel").encode()

    def sentinel_arrived() -> bool:
        attacker.put("fleetlink/site-a/ingest/e1", forbidden)
        attacker.put("fleetlink/site-a/commands/robot1/lightring", forbidden)
        attacker.delete("fleetlink/site-a/events/robot1")
        attacker.put(f"fleetlink/{own_site}/events/x", sentinel)
        return sentinel in _payloads(fleet.at_cloud)

    wait_until(sentinel_arrived, 10, message=f"{own_site}'s own put reaches the cloud")
    return forbidden


def _site_a_still_works(fleet: Fleet) -> None:
    # Site A -> cloud, and cloud -> site A (a command), both after the attack.
    marker = _unique("a-after").encode()
    wait_until(
        lambda: (
            fleet.robot_a.put("fleetlink/site-a/events/y", marker),
            marker in _payloads(fleet.at_cloud_a),
        )[1],
        10,
        message="site A -> cloud",
    )
    command = _unique("command").encode()
    wait_until(
        lambda: (
            fleet.uplink.put("fleetlink/site-a/commands/robot1/x", command),
            command in _payloads(fleet.at_site_a),
        )[1],
        10,
        message="cloud -> site A",
    )


def test_site_b_edge_cannot_publish_into_site_a(fleet: Fleet) -> None:
    forbidden = _attack_then_sentinel(fleet.robot_b, fleet, "site-b")
    _site_a_still_works(fleet)
    assert forbidden not in _payloads(fleet.at_cloud)
    assert forbidden not in _payloads(fleet.at_cloud_a)
    assert forbidden not in _payloads(fleet.at_site_a)
    assert fleet.at_cloud_a.count("fleetlink/site-a/") >= 2  # site A's own puts did arrive


def test_site_b_certificate_cannot_publish_into_site_a_even_without_its_edge_router(fleet: Fleet) -> None:
    # A client holding site B's edge certificate talks to the cloud directly, so no edge-side
    # filter is in the way: only the cloud's ACL stands between it and site A.
    with opened(edge_identity_config(fleet.bundle, "site-b", fleet.cloud_endpoint)) as rogue:
        forbidden = _attack_then_sentinel(rogue, fleet, "site-b")
        _site_a_still_works(fleet)
        assert forbidden not in _payloads(fleet.at_cloud)
        assert forbidden not in _payloads(fleet.at_site_a)


def test_queries_into_another_site_get_no_reply(fleet: Fleet) -> None:
    assert _replies(fleet.robot_b, "fleetlink/site-a/ingest/e1") == []
    assert _replies(fleet.robot_b, "fleetlink/site-a/admin/robots") == []
    assert _replies(fleet.robot_b, "fleetlink/site-b/ingest/e1") == [("fleetlink/site-b/ingest/e1", b"ack")]
    assert _replies(fleet.robot_a, "fleetlink/site-a/ingest/e1") == [("fleetlink/site-a/ingest/e1", b"ack")]
    with opened(edge_identity_config(fleet.bundle, "site-b", fleet.cloud_endpoint)) as rogue:
        assert routers_connected(rogue) == 1
        assert _replies(rogue, "fleetlink/site-a/ingest/e1") == []
        assert _replies(rogue, "fleetlink/site-a/admin/robots") == []
        assert _replies(rogue, "fleetlink/site-b/ingest/e1") == [("fleetlink/site-b/ingest/e1", b"ack")]


def test_cloud_reaches_each_site_admin_space(fleet: Fleet) -> None:
    assert _replies(fleet.uplink, "fleetlink/site-a/admin/robots") == [
        ("fleetlink/site-a/admin/robots", b"admin-a")
    ]
    # A fleet-wide wildcard query reaches every site; each answers on its own keys only.
    assert sorted(_replies(fleet.uplink, "fleetlink/*/admin/robots")) == [
        ("fleetlink/site-a/admin/robots", b"admin-a"),
        ("fleetlink/site-b/admin/robots", b"admin-b"),
    ]


def test_edge_keeps_raw_ros_traffic_and_other_sites_keys_on_the_site(tmp_path: Path) -> None:
    # The cloud here has NO ACL and subscribes to everything: only the edge's rules filter.
    bundle = make_bundle(tmp_path)
    raw_key = "0/robot1/imu/sensor_msgs::msg::dds_::Imu_/RIHS01_00"
    token_key = "@ros2_lv/0/aaaa/0/11/MP/%/%/imu_node/robot1%imu/sensor_msgs::msg::dds_::Imu_/RIHS01_00/x"
    with (
        tls_cloud(bundle, acl=False) as cloud,
        tls_edge(bundle, "site-a", cloud.endpoint) as edge,
        opened(client_config(edge.endpoint)) as robot,
        opened(client_config(edge.endpoint)) as other_robot,
    ):
        at_cloud, tokens_at_cloud = Collector(), Collector()
        on_site, tokens_on_site = Collector(), Collector()
        cloud.session.declare_subscriber("0/**", at_cloud)
        cloud.session.declare_subscriber("fleetlink/**", at_cloud)
        # history=True: tokens declared before the subscriber's interest got through count too.
        cloud.session.liveliness().declare_subscriber("@ros2_lv/**", tokens_at_cloud, history=True)
        other_robot.declare_subscriber("0/**", on_site)
        other_robot.liveliness().declare_subscriber("@ros2_lv/**", tokens_on_site, history=True)
        token = robot.liveliness().declare_token(token_key)
        sentinel = _unique("own").encode()

        def own_put_arrived() -> bool:
            robot.put(raw_key, b"raw")
            robot.put("fleetlink/site-b/events/x", b"other-site")
            robot.put("fleetlink/site-a/events/x", sentinel)
            return sentinel in _payloads(at_cloud)

        wait_until(own_put_arrived, 10, message="site A's fleetlink put reaches the cloud")
        # The site network itself works under the edge's default-deny ACL.
        wait_until(lambda: raw_key in set(on_site.key_exprs()), 5, message="raw data on the site network")
        wait_until(lambda: token_key in set(tokens_on_site.key_exprs()), 5, message="liveliness on the site")
        assert set(at_cloud.key_exprs()) == {"fleetlink/site-a/events/x"}
        assert tokens_at_cloud.key_exprs() == []
        token.undeclare()

        # Control: with this permissive cloud, site B's certificate CAN write into site A's keys,
        # so the checks above and in the fleet tests would see a leak if there were one.
        with opened(edge_identity_config(bundle, "site-b", cloud.endpoint)) as rogue:
            wait_until(
                lambda: (rogue.put("fleetlink/site-a/events/x", b"leak"), b"leak" in _payloads(at_cloud))[1],
                10,
                message="leak without ACL",
            )


def test_dev_variants_carry_fleetlink_keys_and_keep_raw_traffic_on_site() -> None:
    cloud_endpoint = f"tcp/127.0.0.1:{free_port()}"
    site_endpoint = f"tcp/127.0.0.1:{free_port()}"
    cloud_conf = render_router_config(DEPLOY / "cloud-router-dev.json5", listen=[cloud_endpoint])
    edge_conf = render_router_config(
        DEPLOY / "edge-router-dev.json5", site="site-a", listen=[site_endpoint], connect=[cloud_endpoint]
    )
    with (
        opened(cloud_conf) as cloud,
        opened(edge_conf) as edge,
        opened(client_config(site_endpoint)) as robot,
    ):
        assert routers_connected(edge) == 1
        at_cloud = Collector()
        cloud.declare_subscriber("0/**", at_cloud)
        cloud.declare_subscriber("fleetlink/**", at_cloud)
        sentinel = _unique("dev").encode()
        wait_until(
            lambda: (
                robot.put("0/robot1/imu/T/H", b"raw"),
                robot.put("fleetlink/site-a/events/x", sentinel),
                sentinel in _payloads(at_cloud),
            )[2],
            10,
            message="dev: fleetlink put at cloud",
        )
        assert set(at_cloud.key_exprs()) == {"fleetlink/site-a/events/x"}
