"""fleetlink.common.names: one rule per kind of name, the same in config, wire and API."""

from __future__ import annotations

import re

import pytest
from pydantic import BaseModel, ValidationError

from fleetlink.common.names import (
    KafkaTopic,
    KeyChunk,
    NamespaceGlob,
    RosTopic,
    RosType,
    Site,
    cert_name_problem,
    host_id,
    kafka_bad_chars,
    kafka_topic_problem,
    key_chunk_problem,
    key_path_problem,
    ros_type_problem,
    site_problem,
)

pytestmark = pytest.mark.unit


class Names(BaseModel):
    chunk: KeyChunk = "a"
    site: Site = "s"
    topic: KafkaTopic = "t"
    ros_type: RosType = "std_msgs/msg/String"
    ros_topic: RosTopic = "/a"
    glob: NamespaceGlob = "/tb4_*"


@pytest.mark.parametrize("name", ["tb4_01", "edge-1.local", "A", "x" * 100])
def test_key_chunks(name: str) -> None:
    assert key_chunk_problem(name) is None
    assert key_path_problem(name) is None


@pytest.mark.parametrize("name", ["", "a/b", "*", "a b", "x" * 101, "a$", "**"])
def test_not_key_chunks(name: str) -> None:
    assert (
        key_chunk_problem(name)
        == "must be one key chunk: 1 to 100 letters, digits, '_', '.', '-' (no '/', no wildcards)"
    )


def test_robots_may_span_chunks_but_never_wildcards_or_empty_ones() -> None:
    assert key_path_problem("fleet/tb4_01") is None
    for name in ("fleet//tb4", "/tb4", "tb4/*", "tb4 01", ""):
        assert key_path_problem(name) is not None, name


@pytest.mark.parametrize(
    ("site", "problem"),
    [
        ("warehouse-a", None),
        ("9th.floor", None),
        ("s" * 58, None),
        ("s" * 59, "must be one key chunk: 1 to 58"),
        ("_hidden", "must start with a letter or a digit"),
        ("-x", "must start with a letter or a digit"),
        ("a/b", "must be one key chunk"),
    ],
)
def test_sites_also_name_certificates(site: str, problem: str | None) -> None:
    found = site_problem(site)
    assert (found is None) if problem is None else (found is not None and found.startswith(problem))
    if problem is None:
        assert cert_name_problem(f"edge-{site}") is None


def test_certificate_names() -> None:
    assert cert_name_problem("fleetlink-cloud") is None
    assert cert_name_problem("x" * 65) is not None
    assert cert_name_problem(".x") is not None


@pytest.mark.parametrize(
    ("hostname", "expected"),
    [
        ("edge box/01.local", "edge-box-01.local"),
        ("robot_host", "robot_host"),
        ("///", "fallback"),
        ("é", "fallback"),
        ("a" * 63 + "/b", "a" * 63),
        ("x" * 80, "x" * 64),
    ],
)
def test_host_ids_are_key_chunks(hostname: str, expected: str) -> None:
    assert host_id(hostname, "fallback") == expected
    assert key_chunk_problem(expected) is None


def test_kafka_topics() -> None:
    assert kafka_topic_problem("fleet.imu_raw-1") is None
    assert kafka_topic_problem("") == "a Kafka topic name cannot be empty"
    assert kafka_topic_problem("..") == "'..' is not a legal Kafka topic name"
    assert kafka_topic_problem("x" * 250) == "Kafka topic names have at most 249 characters, this one has 250"
    assert kafka_topic_problem("a b/c") == "Kafka topic names use only [a-zA-Z0-9._-]; ' /' is not allowed"
    assert kafka_bad_chars("fleet.{x}") == "{}"


def test_ros_types() -> None:
    assert ros_type_problem("irobot_create_msgs/msg/LightringLeds") is None
    for name in ("Imu", "p/srv/T", "_p/msg/T", "p/msg/", "p/msg/T/x"):
        assert ros_type_problem(name) == "must look like 'package/msg/Type'", name


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("chunk", "a/b", "'a/b' must be one key chunk"),
        ("site", "_x", "'_x' must start with a letter or a digit"),
        ("topic", "a b", "Kafka topic names use only [a-zA-Z0-9._-]; ' ' is not allowed"),
        ("ros_type", "Imu", "ROS type 'Imu' must look like 'package/msg/Type'"),
        ("ros_topic", "imu", "'imu' is not an absolute ROS topic name: not fully qualified"),
        ("glob", "tb4 *", "'tb4 *' is not a namespace glob"),
    ],
)
def test_config_field_types_say_what_is_wrong(field: str, value: str, message: str) -> None:
    assert getattr(Names(), field)
    with pytest.raises(ValidationError, match=re.escape(message)):
        Names.model_validate({field: value})


def test_the_api_documents_the_rules() -> None:
    schema = Names.model_json_schema()["properties"]
    assert schema["chunk"]["pattern"] == "^[A-Za-z0-9_.-]+$"
    assert schema["chunk"]["maxLength"] == 100
    assert schema["site"]["maxLength"] == 58
    assert schema["topic"]["maxLength"] == 249
