"""The mapping table: compile-time validation, robot types, one/many-to-one/many, runtime changes."""

from __future__ import annotations

import pytest

from fleetlink.edge.errors import MappingError, RenderError
from fleetlink.edge.mapping import MappingSpec, MappingTable, RobotTypeSpec, compile_mapping

TB4 = RobotTypeSpec(
    name="turtlebot4",
    match="/tb4_*",
    mappings=(
        MappingSpec(name="ir", source="/{robot}/ir_intensity", topic="fleet.ir_intensity"),
        MappingSpec(name="hazard", source="/{robot}/hazard_detection", topic="fleet.hazards"),
        MappingSpec(name="kidnap", source="/{robot}/kidnap_status", topic="fleet.hazards"),
        MappingSpec(
            name="imu",
            source="/{robot}/imu",
            topic="fleet.imu",
            delivery="best_effort",
            ros_type="sensor_msgs/msg/Imu",
        ),
        MappingSpec(name="all_sensors", source="/{robot}/{sensor}", topic="fleet.raw.{sensor}"),
    ),
)
CREATE3 = RobotTypeSpec(
    name="create3",
    match="/c3_*",
    mappings=(MappingSpec(name="c3_odom", source="/{robot}/odom", topic="fleet.c3.odom", key="c3-{robot}"),),
)
SITE = (
    MappingSpec(name="tasks", source="/{robot}/task_status", topic="fleet.tasks.{msg.zone}"),
    MappingSpec(name="site_map", source="/map", topic="site.map", key="warehouse-a"),
)


def table() -> MappingTable:
    return MappingTable(robot_types=[TB4, CREATE3], mappings=SITE)


def names(topic: str, t: MappingTable) -> list[tuple[str, str | None]]:
    return [(b.name, b.kafka_topic) for b in t.match(topic)]


def test_unregistered_robot_feeds_only_site_mappings() -> None:
    t = table()
    assert names("/tb4_01/ir_intensity", t) == []
    assert [b.name for b in t.match("/tb4_01/task_status")] == ["tasks"]


def test_many_to_one_across_robots_and_topics() -> None:
    t = table()
    assert t.add_robot("tb4_01") == ("ir", "hazard", "kidnap", "imu", "all_sensors")
    t.add_robot("tb4_02")
    for robot in ("tb4_01", "tb4_02"):
        hazard = t.match(f"/{robot}/hazard_detection")
        kidnap = t.match(f"/{robot}/kidnap_status")
        assert [b.kafka_topic for b in hazard] == ["fleet.hazards", "fleet.raw.hazard_detection"]
        assert [b.kafka_topic for b in kidnap] == ["fleet.hazards", "fleet.raw.kidnap_status"]
        assert hazard[0].key == robot
        assert hazard[0].robot == robot
        assert hazard[0].robot_type == "turtlebot4"


def test_bound_mapping_carries_everything_the_pipeline_needs() -> None:
    t = table()
    t.add_robot("tb4_07")
    imu = t.match("/tb4_07/imu")[0]
    assert imu.name == "imu"
    assert imu.source_topic == "/tb4_07/imu"
    assert imu.ros_type == "sensor_msgs/msg/Imu"
    assert imu.delivery == "best_effort"
    assert imu.kafka_topic == "fleet.imu"
    assert imu.key == "tb4_07"
    assert not imu.needs_message_fields
    assert imu.render_topic() == "fleet.imu"
    assert imu.render_key() == "tb4_07"
    assert imu.captures == {"robot": "tb4_07"}
    raw = t.match("/tb4_07/imu")[1]
    assert raw.ros_type is None  # to be discovered
    assert raw.captures == {"robot": "tb4_07", "sensor": "imu"}


def test_one_to_many_by_message_field() -> None:
    t = table()
    (tasks,) = t.match("/tb4_03/task_status")
    assert tasks.needs_message_fields
    assert tasks.kafka_topic is None
    assert tasks.field_paths == (("zone",),)
    assert tasks.render_topic({"zone": "north"}) == "fleet.tasks.north"
    assert tasks.render_topic({"zone": "south"}) == "fleet.tasks.south"
    assert tasks.key == "tb4_03"


@pytest.mark.parametrize(
    ("fields", "reason"),
    [
        ({"zone": "a b"}, "' '"),
        ({"zone": "x" * 240}, "at most 249"),
        ({}, "no field msg.zone"),
        ({"zone": {"n": 1}}, "dict value"),
    ],
)
def test_field_filled_topic_that_is_illegal_is_a_record_error(fields: dict[str, object], reason: str) -> None:
    (tasks,) = table().match("/r9/task_status")
    with pytest.raises(RenderError, match=reason) as info:
        tasks.render_topic(fields)
    assert info.value.mapping == "tasks"


def test_capture_bound_topic_that_is_too_long_is_a_record_error_not_a_crash() -> None:
    t = MappingTable(mappings=[MappingSpec(name="m", source="/{robot}/{s}", topic="t." + "x" * 240 + ".{s}")])
    (bound,) = t.match("/r/abcdefghijk")
    assert bound.kafka_topic is None
    assert bound.topic_error is not None
    with pytest.raises(RenderError, match="at most 249"):
        bound.render_topic({})


def test_key_template_with_fixed_text_and_other_type() -> None:
    t = table()
    t.add_robot("c3_01")
    assert [(b.kafka_topic, b.key) for b in t.match("/c3_01/odom")] == [("fleet.c3.odom", "c3-c3_01")]
    assert t.match("/c3_01/ir_intensity") == ()
    assert t.match("/map")[0].key == "warehouse-a"
    assert t.match("/map")[0].robot is None


def test_remove_robot_drops_its_mappings_only() -> None:
    t = table()
    t.add_robot("tb4_01")
    t.add_robot("tb4_02")
    assert t.remove_robot("tb4_01")
    assert not t.remove_robot("tb4_01")
    assert t.match("/tb4_01/imu") == ()
    assert [b.name for b in t.match("/tb4_02/imu")] == ["imu", "all_sensors"]
    assert t.robots() == {"tb4_02": "turtlebot4"}


def test_robot_type_from_glob_or_explicit() -> None:
    t = table()
    assert t.robot_type_for("tb4_09") == "turtlebot4"
    assert t.robot_type_for("/c3_2") == "create3"
    assert t.robot_type_for("husky") is None
    with pytest.raises(MappingError, match="matches no robot type"):
        t.add_robot("husky")
    with pytest.raises(MappingError, match="unknown robot type 'drone'"):
        t.add_robot("husky", "drone")
    t.add_robot("husky", "create3")
    assert [b.key for b in t.match("/husky/odom")] == ["c3-husky"]


def test_multi_segment_robot_namespace() -> None:
    t = table()
    t.add_robot("fleet/tb4_05", "turtlebot4")
    (imu, raw) = t.match("/fleet/tb4_05/imu")
    assert imu.robot == "fleet/tb4_05"
    assert imu.key == "fleet/tb4_05"
    assert raw.kafka_topic == "fleet.raw.imu"


def test_runtime_add_and_remove_mapping_invalidates_cache() -> None:
    t = table()
    t.add_robot("tb4_01")
    before = t.match("/tb4_01/dock_status")
    assert [b.name for b in before] == ["all_sensors"]
    assert t.match("/tb4_01/dock_status") is before  # cached
    t.add_mapping(MappingSpec(name="dock", source="/{robot}/dock_status", topic="fleet.dock"), "turtlebot4")
    assert [b.name for b in t.match("/tb4_01/dock_status")] == ["all_sensors", "dock"]  # added last
    t.add_mapping(MappingSpec(name="every_dock", source="/{robot}/dock_status", topic="fleet.docks"))
    assert [b.name for b in t.match("/tb4_01/dock_status")] == ["every_dock", "all_sensors", "dock"]
    assert t.remove_mapping("all_sensors")
    assert t.remove_mapping("every_dock")
    assert not t.remove_mapping("nope")
    assert [b.name for b in t.match("/tb4_01/dock_status")] == ["dock"]


def test_add_mapping_rejects_duplicates_and_unknown_type() -> None:
    t = table()
    with pytest.raises(MappingError, match="exists already"):
        t.add_mapping(MappingSpec(name="ir", source="/{robot}/x", topic="x"))
    with pytest.raises(MappingError, match="unknown robot type"):
        t.add_mapping(MappingSpec(name="new", source="/{robot}/x", topic="x"), "drone")
    with pytest.raises(MappingError, match="used twice"):
        MappingTable(mappings=[*SITE, SITE[0]])
    with pytest.raises(MappingError, match="declared twice"):
        MappingTable(robot_types=[CREATE3, RobotTypeSpec(name="create3", match="/x*")])


def test_list_reports_mappings_and_instantiated_robots() -> None:
    t = table()
    t.add_robot("tb4_01")
    t.add_robot("tb4_02")
    info = {i.name: i for i in t.list()}
    assert list(info) == ["tasks", "site_map", "ir", "hazard", "kidnap", "imu", "all_sensors", "c3_odom"]
    assert info["ir"].robots == ("tb4_01", "tb4_02")
    assert info["ir"].key == "{robot}"
    assert info["c3_odom"].robots == ()
    assert info["tasks"].robot_type is None
    assert info["imu"].delivery == "best_effort"


def test_reload_keeps_robots_whose_type_survives() -> None:
    t = table()
    t.add_robot("tb4_01")
    t.add_robot("c3_01")
    version = t.version
    gone = t.reload([TB4], SITE)
    assert gone == ("c3_01",)
    assert t.version > version
    assert t.robots() == {"tb4_01": "turtlebot4"}
    assert t.match("/c3_01/odom") == ()
    with pytest.raises(MappingError):
        t.reload([TB4], [MappingSpec(name="bad", source="/x", topic="bad topic")])
    assert [b.name for b in t.match("/tb4_01/imu")] == ["imu", "all_sensors"]  # unchanged


def test_reload_keeps_the_stage_objects_of_unchanged_mappings() -> None:
    """Adding one mapping must not rebuild the others' stages (their state and counters)."""
    throttle = ({"type": "throttle", "hz": 2},)
    ir = MappingSpec(name="ir", source="/{robot}/ir_intensity", topic="fleet.ir", stages=throttle)
    odom = MappingSpec(name="odom", source="/{robot}/odom", topic="fleet.odom", stages=throttle)
    kind = RobotTypeSpec(name="tb4", match="/tb4_*", mappings=(ir, odom))
    t = MappingTable(robot_types=[kind])
    t.add_robot("tb4_01")
    before = {b.name: b.stages for b in t.match("/tb4_01/ir_intensity") + t.match("/tb4_01/odom")}
    changed = MappingSpec(
        name="odom", source="/{robot}/odom", topic="fleet.odom", stages=({"type": "throttle", "hz": 5},)
    )
    added = MappingSpec(name="imu", source="/{robot}/imu", topic="fleet.imu")
    t.reload([RobotTypeSpec(name="tb4", match="/tb4_*", mappings=(ir, changed, added))], [])
    after = {b.name: b.stages for b in t.match("/tb4_01/ir_intensity") + t.match("/tb4_01/odom")}
    assert after["ir"] is before["ir"]  # unchanged: the same objects
    assert after["odom"] is not before["odom"]  # changed: rebuilt
    assert [b.name for b in t.match("/tb4_01/imu")] == ["imu"]


COMPILE_ERRORS: list[tuple[MappingSpec, str | None, str]] = [
    (
        MappingSpec(name="m", source="/{robot}/{sensor}", topic="fleet.{sensr}"),
        None,
        "uses {sensr}, which the pattern '/{robot}/{sensor}' does not capture",
    ),
    (
        MappingSpec(name="m", source="/{robot}/imu", topic="fleet.imu", key="{robt}"),
        None,
        "key template '{robt}' uses {robt}",
    ),
    (MappingSpec(name="m", source="/map", topic="site.map"), None, "captures no robot"),
    (MappingSpec(name="m", source="/map", topic="site map", key="k"), None, "' ' is not allowed"),
    (MappingSpec(name="m", source="/{r}/x", topic="t/{r}", key="k"), None, "'/' is not allowed"),
    (MappingSpec(name="m", source="/map", topic="a" * 250, key="k"), None, "at most 249"),
    (MappingSpec(name="m", source="/map", topic="t", key="k"), "turtlebot4", "must capture the robot"),
    (MappingSpec(name="m", source="/{robot*}/x", topic="t"), "turtlebot4", "must capture the robot"),
    (MappingSpec(name="m", source="/{robot}/x", topic="t", ros_type="Imu"), None, "package/msg/Type"),
    (MappingSpec(name="bad name", source="/{robot}/x", topic="t"), None, "mapping name"),
    (
        MappingSpec(name="m", source="/{robot}/x", topic="t", delivery="maybe"),  # type: ignore[arg-type]
        None,
        "delivery 'maybe'",
    ),
]


@pytest.mark.parametrize(("spec", "robot_type", "reason"), COMPILE_ERRORS)
def test_compile_errors_name_mapping_and_template(
    spec: MappingSpec, robot_type: str | None, reason: str
) -> None:
    with pytest.raises(MappingError) as info:
        compile_mapping(spec, robot_type=robot_type)
    assert reason in str(info.value)
    if spec.name == "m":
        assert str(info.value).startswith("mapping 'm': ")


def test_match_is_fast_with_many_robots() -> None:
    t = MappingTable(robot_types=[TB4])
    for i in range(200):
        t.add_robot(f"tb4_{i:03d}")
    topics = [f"/tb4_{i:03d}/{s}" for i in range(200) for s in ("imu", "hazard_detection", "odom")]
    first = [t.match(topic) for topic in topics]
    assert all(len(m) >= 1 for m in first)
    assert [t.match(topic) for topic in topics] == first
    assert all(a is b for a, b in zip(first, [t.match(topic) for topic in topics], strict=True))


def test_a_topic_awaits_its_robot_only_where_a_robot_type_would_take_it() -> None:
    t = table()
    assert t.awaits_robot("/tb4_01/ir_intensity")  # tb4_01 matches /tb4_* and is not registered
    assert t.awaits_robot("/c3_02/odom")
    assert not t.awaits_robot("/c3_02/ir_intensity")  # c3 robots have no such mapping
    assert not t.awaits_robot("/other_1/ir_intensity")  # no robot type matches other_1
    assert not t.awaits_robot("/map")
    t.add_robot("tb4_01")
    assert not t.awaits_robot("/tb4_01/ir_intensity")  # registered: a mapping takes it now
