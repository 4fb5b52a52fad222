"""Loading standard, custom-package and bag-embedded type definitions."""

from __future__ import annotations

from pathlib import Path

import pytest
from rosbags.interfaces import Nodetype

from fleetlink.schemas.errors import TypeDefinitionError, UnknownTypeError
from fleetlink.schemas.typestore import (
    EMPTY_MEMBER,
    load_typestore,
    message_types,
    normalize_typename,
    types_from_msg,
    types_from_srv,
)
from tests.paths import BAGS, IROBOT


@pytest.mark.parametrize(
    ("distro", "typename", "present"),
    [
        ("humble", "sensor_msgs/msg/Imu", True),
        ("jazzy", "service_msgs/msg/ServiceEventInfo", True),
        ("humble", "service_msgs/msg/ServiceEventInfo", False),
        ("kilted", "nav_msgs/msg/Odometry", True),
    ],
)
def test_standard_types_per_distro(distro: str, typename: str, present: bool) -> None:
    ts = load_typestore(distro)  # type: ignore[arg-type]
    assert (typename in message_types(ts)) is present


def test_unknown_distro() -> None:
    with pytest.raises(TypeDefinitionError):
        load_typestore("rolling")  # type: ignore[arg-type]


def test_custom_package_folder() -> None:
    ts = load_typestore("jazzy", msg_paths=[IROBOT])
    names = message_types(ts)
    assert "irobot_create_msgs/msg/LightringLeds" in names
    assert "irobot_create_msgs/srv/ResetPose_Request" in names
    assert "irobot_create_msgs/srv/ResetPose_Response" in names
    leds = dict(ts.fielddefs["irobot_create_msgs/msg/LightringLeds"][1])
    assert leds["leds"] == (Nodetype.ARRAY, ((Nodetype.NAME, "irobot_create_msgs/msg/LedColor"), 6))
    # an empty request gets the member rosidl adds
    assert ts.fielddefs["irobot_create_msgs/srv/RobotPower_Request"][1] == [EMPTY_MEMBER]


def test_bag_definitions_are_loaded() -> None:
    ts = load_typestore("humble", bags=[BAGS / "robot_localization_husky", BAGS / "fuse_turtlebot3_sim"])
    for name in ("sensor_msgs/msg/NavSatFix", "sensor_msgs/msg/JointState", "sensor_msgs/msg/LaserScan"):
        assert name in message_types(ts)


def test_missing_nested_type_in_package(tmp_path: Path) -> None:
    (tmp_path / "msg").mkdir()
    (tmp_path / "msg" / "Outer.msg").write_text("Inner inner\nint32 x\n")
    with pytest.raises(UnknownTypeError) as info:
        load_typestore("jazzy", msg_paths=[tmp_path])
    assert info.value.typename == f"{tmp_path.name}/msg/Inner"
    assert info.value.referenced_by == f"{tmp_path.name}/msg/Outer.inner"


def test_package_name_from_manifest(tmp_path: Path) -> None:
    pkg = tmp_path / "folder"
    (pkg / "msg").mkdir(parents=True)
    (pkg / "package.xml").write_text("<package><name>real_name</name></package>")
    (pkg / "msg" / "A.msg").write_text("int8 a\n")
    assert "real_name/msg/A" in message_types(load_typestore("jazzy", msg_paths=[pkg]))


def test_conflicting_definition_names_the_type(tmp_path: Path) -> None:
    pkg = tmp_path / "std_msgs"
    (pkg / "msg").mkdir(parents=True)
    (pkg / "msg" / "String.msg").write_text("int32 data\n")
    with pytest.raises(TypeDefinitionError) as info:
        load_typestore("jazzy", msg_paths=[pkg])
    assert info.value.typename == "std_msgs/msg/String"


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("int64 a\n", "one '---'"),
        ("int64 a\n---\nint64 b\n---\nint64 c\n", "one '---'"),
    ],
)
def test_bad_service_definitions(text: str, problem: str) -> None:
    with pytest.raises(TypeDefinitionError, match=problem):
        types_from_srv(text, "p/srv/S")


def test_service_short_names_resolve_into_msg_folder() -> None:
    types = types_from_srv("Thing t\n---\nbool ok\n", "p/srv/S")
    assert dict(types["p/srv/S_Request"][1])["t"] == (Nodetype.NAME, "p/msg/Thing")


@pytest.mark.parametrize(
    ("text", "typename"),
    [("int32 x\n!!!\n", "p/msg/Bad"), ("float32[ x\n", "p/msg/Bad")],
)
def test_unparsable_msg(text: str, typename: str) -> None:
    with pytest.raises(TypeDefinitionError) as info:
        types_from_msg(text, typename)
    assert info.value.typename == typename


@pytest.mark.parametrize(
    ("given", "normal"),
    [
        ("std_msgs/String", "std_msgs/msg/String"),
        ("/std_msgs/msg/String", "std_msgs/msg/String"),
        ("example_interfaces/srv/AddTwoInts", "example_interfaces/srv/AddTwoInts"),
    ],
)
def test_normalize_typename(given: str, normal: str) -> None:
    assert normalize_typename(given) == normal


def test_not_a_directory(tmp_path: Path) -> None:
    with pytest.raises(TypeDefinitionError):
        load_typestore("jazzy", msg_paths=[tmp_path / "absent"])
