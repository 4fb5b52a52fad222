"""The edge config model: every deploy/edge*.yaml loads; bad configs name the exact YAML path."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from fleetlink.common.configfile import load_config
from fleetlink.common.errors import ConfigError
from fleetlink.edge.config import EdgeConfig, default_edge_id
from tests.paths import DEPLOY

EXAMPLES = sorted(DEPLOY.glob("edge*.yaml"))

BASE = """\
site: warehouse-a
spool: {dir: /var/lib/fleetlink/spool}
robot_types:
  turtlebot4:
    match: "/tb4_*"
    mappings:
      - name: ir
        from: "/{robot}/ir_intensity"
        to: fleet.ir_intensity
"""


def load(tmp_path: Path, text: str) -> EdgeConfig:
    path = tmp_path / "edge.yaml"
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return load_config(EdgeConfig, path)


def test_there_is_an_example_to_load() -> None:
    assert DEPLOY / "edge.example.yaml" in EXAMPLES


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_every_deploy_edge_config_loads_and_builds_its_mappings(path: Path) -> None:
    config = load_config(EdgeConfig, path)
    table = config.mapping_table()
    for robot_type, spec in config.robot_types.items():
        robot = spec.match.strip("/").replace("*", "x").replace("?", "x")
        assert table.add_robot(robot) == tuple(m.name for m in spec.mappings)
        assert table.robots()[robot] == robot_type
    declared = len(config.mappings) + sum(len(t.mappings) for t in config.robot_types.values())
    assert len(table.list()) == declared
    config.spool.options()
    config.memory.buffer().close()


def test_the_example_declares_what_the_warehouse_needs() -> None:
    config = load_config(EdgeConfig, DEPLOY / "edge.example.yaml")
    table = config.mapping_table()
    table.add_robot("tb4_01")
    table.add_robot("tb4_02")
    for topic, kafka in [
        ("ir_intensity", "fleet.ir_intensity"),
        ("hazard_detection", "fleet.hazards"),
        ("kidnap_status", "fleet.kidnap"),
    ]:
        bound = [b for r in ("tb4_01", "tb4_02") for b in table.match(f"/{r}/{topic}")]
        assert [(b.kafka_topic, b.key) for b in bound] == [(kafka, "tb4_01"), (kafka, "tb4_02")]
    (odom,) = table.match("/tb4_01/odom")
    assert [s.type for s in odom.stages] == ["aggregate"]
    assert odom.linger_s == 1.0  # an aggregate's records may wait one window for company
    (imu,) = table.match("/tb4_01/imu")
    assert imu.delivery == "best_effort"
    (tasks,) = table.match("/tb4_01/task_status")
    assert tasks.render_topic({"zone": "north"}) == "fleet.tasks.north"
    assert config.wan.linger == 20_000_000
    assert config.spool.options().fsync_interval_ms == 100


def test_minimal_config_and_defaults(tmp_path: Path) -> None:
    config = load(tmp_path, "site: s1\nspool: {dir: spool}\n")
    assert config.edge_id == default_edge_id()
    assert config.ros.distro == "jazzy"
    assert config.registration.grace_period == 5_000_000_000
    assert config.spool.options().policy == "block"
    assert config.wan.codec == "zstd"
    assert config.intake.coalesce == 1_000_000
    assert config.admin is None
    assert config.mapping_table().list() == []


AGGREGATE = "{type: aggregate, window: %s, fields: [x], ops: [mean]}"


@pytest.mark.parametrize(
    ("extra", "expected_s"),
    [
        ("", None),  # the edge's wan.linger
        ("        linger: 250ms\n", 0.25),
        (f"        stages: [{AGGREGATE % '2s'}]\n", 2.0),
        (f"        stages: [{AGGREGATE % '2s'}]\n        linger: 0s\n", 0.0),
        (f"        stages: [{AGGREGATE % '1m'}]\n", 5.0),
        ("        stages: [{type: aggregate, window: 10s, hop: 3s, fields: [x], ops: [max]}]\n", 3.0),
    ],
)
def test_mapping_linger_defaults_to_the_aggregate_period(
    tmp_path: Path, extra: str, expected_s: float | None
) -> None:
    config = load(tmp_path, BASE + extra)
    table = config.mapping_table()
    table.add_robot("tb4_01")
    (bound,) = table.match("/tb4_01/ir_intensity")
    assert bound.linger_s == expected_s


def test_default_edge_id_is_a_key_chunk(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("socket.gethostname", lambda: "edge box/01.local")
    assert default_edge_id() == "edge-box-01.local"
    monkeypatch.setattr("socket.gethostname", lambda: "///")
    assert default_edge_id() == "edge"


M0 = "robot_types.turtlebot4.mappings[0]"
SPOOL = "spool: {dir: /var/lib/fleetlink/spool}"
VE = "Value error, "

BAD: list[tuple[str, str, str]] = [
    ("unknown top-level key", BASE + "sitee: x\n", "sitee (line 10): unknown key"),
    ("unknown key in a mapping", BASE + "        topic: x\n", f"{M0}.topic (line 10): unknown key"),
    (
        "wrong type",
        BASE + "wan: {max_in_flight: eight}\n",
        "wan.max_in_flight (line 10): Input should be a valid integer",
    ),
    (
        "bad size",
        BASE.replace(SPOOL, "spool: {dir: /s, max_bytes: lots}"),
        "spool.max_bytes (line 2): could not parse",
    ),
    (
        "bad template capture",
        BASE.replace("to: fleet.ir_intensity", "to: fleet.{sensor}"),
        f"{M0}.to (line 9): {VE}Kafka topic template 'fleet.{{sensor}}' uses {{sensor}}, which the pattern "
        "'/{robot}/ir_intensity' does not capture",
    ),
    (
        "bad key capture",
        BASE + "        key: '{sensor}'\n",
        f"{M0}.key (line 10): {VE}key template '{{sensor}}' uses {{sensor}}",
    ),
    (
        "illegal topic",
        BASE.replace("to: fleet.ir_intensity", "to: fleet ir"),
        f"{M0}.to (line 9): {VE}Kafka topic 'fleet ir': Kafka topic names use only [a-zA-Z0-9._-]; "
        "' ' is not allowed",
    ),
    (
        "bad duration",
        BASE + "registration: {grace_period: 5 parsecs}\n",
        f"registration.grace_period (line 10): {VE}invalid duration '5 parsecs'",
    ),
    ("bad duration in wan", BASE + "wan: {linger: -1}\n", f"wan.linger (line 10): {VE}duration must not be"),
    (
        "robot type mapping without {robot}",
        BASE.replace('"/{robot}/ir_intensity"', '"/ir_intensity"'),
        f"{M0}.from (line 8): {VE}'/ir_intensity': a robot type's mappings capture the robot",
    ),
    (
        "bad pattern",
        BASE.replace('"/{robot}/ir_intensity"', '"/{robot}/ir-intensity"'),
        f"{M0}.from (line 8): {VE}topic pattern '/{{robot}}/ir-intensity': segment 'ir-intensity'",
    ),
    (
        "site mapping without robot or key",
        BASE + "mappings:\n  - {name: m, from: /map, to: site.map}\n",
        f"mappings[0].key (line 11): {VE}the key defaults to '{{robot}}' "
        "but 'from' ('/map') captures no robot",
    ),
    (
        "duplicate names",
        BASE + "mappings:\n  - {name: ir, from: '/{robot}/x', to: x}\n",
        f"<root>: {VE}mapping name 'ir' is used twice (mappings[0] and {M0})",
    ),
    ("bad ros type", BASE + "        type: Imu\n", f"{M0}.type (line 10): {VE}ROS type 'Imu' must look like"),
    (
        "bad stage",
        BASE + "        stages: [{type: throttle, hz: 0}]\n",
        f"{M0}.stages[0].throttle.hz (line 10): Input should be greater than 0",
    ),
    (
        "bad delivery",
        BASE + "        delivery: sometimes\n",
        f"{M0}.delivery (line 10): Input should be 'at_least_once' or 'best_effort'",
    ),
    (
        "bad glob",
        BASE.replace('match: "/tb4_*"', 'match: "/tb4 *"'),
        f"robot_types.turtlebot4.match (line 5): {VE}'/tb4 *' is not a namespace glob",
    ),
    (
        "bad robot type name",
        BASE.replace("turtlebot4:", "turtle bot:"),
        "robot_types.turtle bot.[key] (line 4): Value error, 'turtle bot' must be one key chunk",
    ),
    (
        "site with a slash",
        BASE.replace("site: warehouse-a", "site: a/b"),
        f"site (line 1): {VE}'a/b' must be one key chunk",
    ),
    (
        "site with a wildcard",
        BASE.replace("site: warehouse-a", "site: '*'"),
        f"site (line 1): {VE}'*' must be",
    ),
    (
        "segment too big",
        BASE.replace(SPOOL, "spool: {dir: /s, max_bytes: 1MiB, segment_bytes: 1MiB}"),
        f"spool (line 2): {VE}max_bytes (1048576) must be at least twice segment_bytes",
    ),
    (
        "backoff upside down",
        BASE + "wan: {retry_backoff_min: 10s, retry_backoff_max: 1s}\n",
        f"wan (line 10): {VE}retry_backoff_min must be above 0s and at most retry_backoff_max",
    ),
    ("missing spool", "site: s\n", "spool: Field required"),
    ("bad admin listen", BASE + "admin: {listen: localhost}\n", f"admin.listen (line 10): {VE}'localhost'"),
    (
        "bad registration topic",
        BASE + "registration: {topic: register}\n",
        f"registration.topic (line 10): {VE}'register' is not an absolute ROS topic name",
    ),
    ("bad distro", BASE + "ros: {distro: foxy}\n", "ros.distro (line 10): Input should be 'humble'"),
    ("coalesce too long", BASE + "intake: {coalesce: 1s}\n", "intake.coalesce (line 10): Input should be"),
    (
        "linger too long",
        BASE + "        linger: 2m\n",
        f"{M0}.linger (line 10): {VE}linger must be between 0s and 60s",
    ),
]


@pytest.mark.parametrize(("text", "expected"), [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_configs_name_the_yaml_path(tmp_path: Path, text: str, expected: str) -> None:
    with pytest.raises(ConfigError) as info:
        load(tmp_path, text)
    assert expected in str(info.value)


CAMERA = """\
site: warehouse-a
spool: {dir: /var/lib/fleetlink/spool}
robot_types:
  turtlebot4:
    match: "/tb4_*"
    mappings:
      - name: camera
        from: "/{robot}/oakd/rgb/preview/image_raw"
        to: fleet.images
        stages: [{type: compress_image, format: jpeg, quality: 85}]
        claim_check: {above: 64KiB}
"""


def test_a_claim_check_without_an_object_store_names_the_mapping(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"robot_types\.turtlebot4\.mappings\[0\]\.claim_check"):
        load(tmp_path, CAMERA)


def test_a_camera_mapping_with_an_object_store_loads(tmp_path: Path) -> None:
    config = load(
        tmp_path,
        CAMERA
        + "objects: {endpoint: 'http://127.0.0.1:9000', bucket: fleet-images, access_key_id: k, "
        + "secret_access_key: s}\nwan: {oversize: drop, max_record_bytes: 500KB}\n",
    )
    [mapping] = config.robot_types["turtlebot4"].mappings
    assert mapping.claim_check is not None
    assert int(mapping.claim_check.above) == 64 << 10
    assert config.wan.oversize == "drop"
    assert config.wan.max_record_bytes == 500_000
    with pytest.raises(ConfigError, match=r"wan\.oversize"):
        load(tmp_path, BASE + "wan: {oversize: split}\n")


def test_the_admin_overlay_keeps_the_object_stores_inline_secret(tmp_path: Path) -> None:
    from fleetlink.edge.admin.overlay import config_data

    config = load(
        tmp_path,
        BASE + "objects: {endpoint: 'http://127.0.0.1:9000', bucket: b1b, access_key_id: k, "
        "secret_access_key: s3cr3t}\n",
    )
    again = EdgeConfig.model_validate(config_data(config))
    assert again.objects is not None
    assert again.objects.resolve_secret() == "s3cr3t"
    assert "s3cr3t" not in str(config.model_dump(mode="json"))  # shown nowhere else
