"""The Java app's Maven project, read as files: its schemas, its pins, its log lines, its command line."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from fleetlink.examples import kafka_streams
from fleetlink.schemas.avro_schema import avro_fullname, avro_schema
from fleetlink.schemas.typestore import load_typestore
from tests.paths import IROBOT

POM = kafka_streams.PROJECT / "pom.xml"
NS = {"m": "http://maven.apache.org/POM/4.0.0"}
TYPES = [
    "irobot_create_msgs/msg/IrIntensityVector",
    "irobot_create_msgs/msg/HazardDetectionVector",
    "irobot_create_msgs/msg/KidnapStatus",
    "irobot_create_msgs/msg/LightringLeds",
]


def test_the_avro_files_are_what_fleetlink_schemas_export_writes() -> None:
    """The classes are generated from the schemas fleetlink registers: a changed generator shows here."""
    ts = load_typestore("jazzy", [IROBOT])
    folder = kafka_streams.PROJECT / "src" / "main" / "avro"
    expected = {f"{avro_fullname(t)}.avsc": avro_schema(ts, t, "jazzy") for t in TYPES}
    found = {p.name: json.loads(p.read_text()) for p in folder.glob("*.avsc")}
    assert found == expected


def _pom() -> ET.Element:
    return ET.parse(POM).getroot()


def _version(node: ET.Element, properties: dict[str, str]) -> str | None:
    version = node.findtext("m:version", namespaces=NS)
    if version is None:
        return None
    return re.sub(r"\$\{([^}]+)\}", lambda m: properties[m.group(1)], version)


def test_every_plugin_and_dependency_is_pinned_to_a_release() -> None:
    root = _pom()
    declared = root.find("m:properties", NS)
    assert declared is not None
    properties = {child.tag.split("}")[1]: child.text or "" for child in declared}
    managed = {
        (d.findtext("m:groupId", namespaces=NS), d.findtext("m:artifactId", namespaces=NS))
        for d in root.iterfind("m:build/m:pluginManagement/m:plugins/m:plugin", NS)
    }
    nodes = [
        *root.iterfind(".//m:dependency", NS),
        *root.iterfind("m:build/m:pluginManagement/m:plugins/m:plugin", NS),
        *root.iterfind("m:build/m:plugins/m:plugin", NS),
    ]
    assert len(nodes) > 10
    for node in nodes:
        coordinates = (
            node.findtext("m:groupId", namespaces=NS),
            node.findtext("m:artifactId", namespaces=NS),
        )
        version = _version(node, properties)
        if version is None:
            assert coordinates in managed, f"{coordinates} has no version"
            continue
        assert re.fullmatch(r"\d+(\.\d+)+", version), f"{coordinates}: {version} is not a pinned release"
    # the lifecycle plugins `package` runs are pinned too (else Maven picks its built-in versions)
    for plugin in (
        "maven-resources-plugin",
        "maven-compiler-plugin",
        "maven-surefire-plugin",
        "maven-jar-plugin",
    ):
        assert ("org.apache.maven.plugins", plugin) in managed
    assert root.find("m:repositories", NS) is None, "Maven Central only"
    assert root.find("m:pluginRepositories", NS) is None, "Maven Central only"


def test_state_changes_are_read_from_the_log() -> None:
    line = (
        "2026-01-01T00:00:00.000 INFO Main - robot=tb4_02 state=running->failed window_end_ms=1700000004000 "
        "events=61 failures=61 command_id=tb4_02-failed-1700000004000"
    )
    change = kafka_streams.parse_state_change(line)
    assert change == kafka_streams.StateChange(
        "tb4_02", "running", "failed", 1700000004000, "tb4_02-failed-1700000004000"
    )
    assert kafka_streams.parse_state_change("2026-01-01 INFO Main - running: application.id=x") is None
    assert kafka_streams.parse_state_change("robot=tb4_02 state=failed") is None


def test_the_command_line_passes_the_native_registry_url(tmp_path: Path) -> None:
    argv = kafka_streams.command(
        "/usr/bin/java",
        bootstrap="127.0.0.1:9092",
        registry_native_url="http://127.0.0.1:8081/apis/registry/v3",
        window_ms=1500,
        group="g",
        state_dir=tmp_path,
        from_beginning=True,
        extra=("-v",),
    )
    assert argv[0] == "/usr/bin/java"
    assert argv[argv.index("-jar") + 1] == str(kafka_streams.JAR)
    pairs = dict(zip(argv[argv.index("-jar") + 2 :: 2], argv[argv.index("-jar") + 3 :: 2], strict=False))
    assert pairs["--registry"] == "http://127.0.0.1:8081/apis/registry/v3"
    assert pairs["--window"] == "1500ms"
    assert pairs["--group"] == "g"
    assert argv[-2:] == ["--from-beginning", "-v"]


def test_a_missing_maven_is_named(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("shutil.which", lambda _name: None)
    with pytest.raises(kafka_streams.JavaAppError, match="Maven"):
        kafka_streams.build()
