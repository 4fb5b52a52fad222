"""Topic patterns and templates: parsing, matching, binding, rendering, Kafka topic legality."""

from __future__ import annotations

from typing import Any

import pytest

from fleetlink.common.names import kafka_topic_problem
from fleetlink.edge.errors import MappingError, RenderError
from fleetlink.edge.mapping import Template, TopicPattern

MATCHES: list[tuple[str, str, dict[str, str] | None]] = [
    ("/{robot}/imu", "/tb4_01/imu", {"robot": "tb4_01"}),
    ("/{robot}/imu", "/tb4_01/imu/data", None),
    ("/{robot}/imu", "/fleet/tb4_01/imu", None),
    ("/{robot}/imu", "/imu", None),
    ("/{robot}/{sensor}", "/tb4_01/ir_intensity", {"robot": "tb4_01", "sensor": "ir_intensity"}),
    ("/{robot}/{sensor}", "/tb4_01/a/b", None),
    ("/{robot}/{a}/{b}", "/r1/x/y", {"robot": "r1", "a": "x", "b": "y"}),
    ("/{robot}/{rest*}", "/r1/x", {"robot": "r1", "rest": "x"}),
    ("/{robot}/{rest*}", "/r1/x/y/z", {"robot": "r1", "rest": "x/y/z"}),
    ("/{robot}/{rest*}", "/r1", None),
    ("/{ns*}/odom", "/site/a/r1/odom", {"ns": "site/a/r1"}),
    ("/map", "/map", {}),
    ("/map", "/map2", None),
]


@pytest.mark.parametrize(("pattern", "topic", "expected"), MATCHES)
def test_pattern_matches(pattern: str, topic: str, expected: dict[str, str] | None) -> None:
    assert TopicPattern.parse(pattern).match(topic) == expected


BAD_PATTERNS: list[tuple[str, str]] = [
    ("imu", "absolute ROS name"),
    ("/", "absolute ROS name"),
    ("/{robot}/imu/", "must not end"),
    ("/{robot}//imu", "empty segment"),
    ("/{robot}_x/imu", "whole segment"),
    ("/{robot}/{robot}", "appears twice"),
    ("/{a*}/{b*}", "at most one multi-segment"),
    ("/{msg}/x", "reserved"),
    ("/a.b/{x}", "letters, digits"),
    ("/{1x}/imu", "whole segment"),
    ("/{robot/imu", "whole segment"),
]


@pytest.mark.parametrize(("pattern", "reason"), BAD_PATTERNS)
def test_bad_patterns_are_rejected_naming_mapping(pattern: str, reason: str) -> None:
    with pytest.raises(MappingError, match=reason) as info:
        TopicPattern.parse(pattern, mapping="imu_map")
    assert "mapping 'imu_map'" in str(info.value)
    assert info.value.template == pattern


def test_bind_replaces_capture_by_literal_segments() -> None:
    pattern = TopicPattern.parse("/{robot}/{sensor}").bind({"robot": "fleet/tb4_01"})
    assert pattern.text == "/fleet/tb4_01/{sensor}"
    assert pattern.captures == ("sensor",)
    assert pattern.match("/fleet/tb4_01/imu") == {"sensor": "imu"}
    assert pattern.match("/tb4_01/imu") is None
    assert TopicPattern.parse("/{robot}/imu").bind({"robot": "r1"}).is_literal


TOPIC_NAMES: list[tuple[str, str | None]] = [
    ("fleet.imu", None),
    ("a" * 249, None),
    ("a" * 250, "at most 249"),
    ("", "empty"),
    (".", "not a legal"),
    ("..", "not a legal"),
    ("fleet/imu", "'/'"),
    ("fleet imu", "' '"),
    ("Fleet_IMU-1.x", None),
]


@pytest.mark.parametrize(("name", "problem"), TOPIC_NAMES)
def test_kafka_topic_legality(name: str, problem: str | None) -> None:
    found = kafka_topic_problem(name)
    if problem is None:
        assert found is None
    else:
        assert found is not None
        assert problem in found


TEMPLATES: list[tuple[str, dict[str, str], dict[str, Any] | None, str]] = [
    ("fleet.{sensor}", {"sensor": "imu"}, None, "fleet.imu"),
    ("fleet.tasks.{msg.zone}", {}, {"zone": "z3"}, "fleet.tasks.z3"),
    ("{robot}-{msg.header.frame_id}", {"robot": "r1"}, {"header": {"frame_id": "base"}}, "r1-base"),
    ("x.{msg.n}", {}, {"n": 7}, "x.7"),
    ("x.{msg.f}", {}, {"f": 2.0}, "x.2"),
    ("x.{msg.f}", {}, {"f": 2.5}, "x.2.5"),
    ("x.{msg.b}", {}, {"b": True}, "x.true"),
    ("{{literal}}.{robot}", {"robot": "r"}, None, "{literal}.r"),
    ("plain", {}, None, "plain"),
]


@pytest.mark.parametrize(("text", "captures", "fields", "expected"), TEMPLATES)
def test_template_bind_and_render(
    text: str, captures: dict[str, str], fields: dict[str, Any] | None, expected: str
) -> None:
    template = Template.parse(text).bind(captures)
    assert template.render(fields, mapping="m") == expected


def test_multi_segment_capture_renders_with_dots_in_topics_only() -> None:
    template = Template.parse("fleet.{rest}")
    assert template.bind({"rest": "a/b/c"}, for_topic=True).render(None, mapping="m") == "fleet.a.b.c"
    assert template.bind({"rest": "a/b/c"}).render(None, mapping="m") == "fleet.a/b/c"


RENDER_ERRORS: list[tuple[str, dict[str, Any] | None, str]] = [
    ("t.{msg.zone}", {}, "no field msg.zone"),
    ("t.{msg.a.b}", {"a": 3}, "no field msg.a.b"),
    ("t.{msg.zone}", None, "no message"),
    ("t.{msg.zone}", {"zone": [1, 2]}, "list value"),
    ("t.{msg.zone}", {"zone": float("nan")}, "cannot name"),
    ("t.{msg.zone}", {"zone": None}, "NoneType"),
    ("t.{robot}", {}, "never bound"),
]


@pytest.mark.parametrize(("text", "fields", "reason"), RENDER_ERRORS)
def test_render_errors_are_per_record(text: str, fields: dict[str, Any] | None, reason: str) -> None:
    with pytest.raises(RenderError, match=reason) as info:
        Template.parse(text).render(fields, mapping="tasks")
    assert info.value.mapping == "tasks"
    assert info.value.template == text


BAD_TEMPLATES: list[tuple[str, str]] = [
    ("fleet.{sensor", "unclosed"),
    ("fleet.sensor}", "unmatched"),
    ("fleet.{}", "not a capture name"),
    ("fleet.{a-b}", "not a capture name"),
    ("fleet.{header.x}", "start with 'msg.'"),
    ("fleet.{msg}", "needs a field path"),
]


@pytest.mark.parametrize(("text", "reason"), BAD_TEMPLATES)
def test_bad_templates(text: str, reason: str) -> None:
    with pytest.raises(MappingError, match=reason):
        Template.parse(text, mapping="m")


def test_template_introspection() -> None:
    template = Template.parse("fleet.{robot}.{msg.zone}.{msg.a.b}.{msg.zone}")
    assert template.captures == frozenset({"robot"})
    assert template.field_paths == (("zone",), ("a", "b"))
    assert not template.is_literal
    assert template.literal_text == "fleet...."
