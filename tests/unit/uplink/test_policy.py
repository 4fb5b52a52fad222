"""Where a site may write: its patterns, and never a topic fleetlink owns."""

from __future__ import annotations

import pytest

from fleetlink.uplink.policy import InternalTopics, TopicPolicy, pattern_problem

INTERNAL = InternalTopics(
    "fleetlink.robots",
    "fleetlink.dead-letter",
    frozenset({"fleetlink.commands.status", "fleet.commands.lightring", "ops.refused"}),
)


def policy() -> TopicPolicy:
    return TopicPolicy({"site-a": ["fleet.*", "{site}.*"]}, ["fleet.*"], INTERNAL)


@pytest.mark.parametrize(
    ("site", "topic", "route", "reason"),
    [
        ("site-a", "fleet.imu", "produce", ""),
        ("site-a", "site-a.imu", "produce", ""),
        ("site-b", "site-a.imu", "refuse", "may not write to topic 'site-a.imu'"),  # default patterns
        ("site-b", "fleet.imu", "produce", ""),
        ("site-b", "fleetlink.robots", "registration", ""),
        ("site-b", "fleetlink.dead-letter", "dead_letter", ""),
        ("site-b", "fleetlink.commands.status", "refuse", "fleetlink's own"),
        ("site-b", "fleet.commands.lightring", "refuse", "fleetlink's own"),  # a command topic
        ("site-b", "ops.refused", "refuse", "fleetlink's own"),
        ("site-a", "fleetlink.anything", "refuse", "fleetlink's own"),
        ("site-a", "_schemas", "refuse", "fleetlink's own"),
        ("site-a", "__consumer_offsets", "refuse", "fleetlink's own"),
    ],
)
def test_decisions(site: str, topic: str, route: str, reason: str) -> None:
    decision = policy().decide(site, topic)
    assert decision.route == route
    assert reason in decision.reason


def test_routes_lists_only_what_is_not_produced_as_is() -> None:
    p = policy()
    assert p.routes("site-a", ["fleet.a", "fleet.b"]) == {}
    assert set(p.routes("site-a", ["fleet.a", "fleetlink.robots", "x"])) == {"fleetlink.robots", "x"}
    assert p.decide("site-a", "x") is p.decide("site-a", "x")  # decided once


def test_the_default_policy_lets_a_site_write_any_topic_but_fleetlinks() -> None:
    p = TopicPolicy({}, ["*"], INTERNAL)
    assert p.decide("s", "anything.at-all").route == "produce"
    assert p.decide("s", "fleetlink.x").route == "refuse"


@pytest.mark.parametrize(
    ("pattern", "ok"), [("fleet.*", True), ("{site}.x", True), ("a b", False), ("", False)]
)
def test_patterns(pattern: str, ok: bool) -> None:
    assert (pattern_problem(pattern) is None) == ok
