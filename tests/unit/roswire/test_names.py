"""Names, DDS type names and data keys, pinned against rmw_zenoh.md §2 and §12."""

from __future__ import annotations

import pytest

from fleetlink.roswire.errors import InvalidNameError, KeyParseError
from fleetlink.roswire.names import (
    DataKey,
    data_key,
    data_key_expr,
    dds_type_name,
    first_segment,
    is_valid_type_hash,
    mangle,
    parse_data_key,
    resolve_topic,
    ros_type_name,
    service_key_type,
    unmangle,
    validate_namespace,
    validate_topic,
)

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
TWIST_HASH = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
ADD_TWO_INTS_HASH = "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"


@pytest.mark.parametrize(
    ("plain", "mangled"),
    [("/", "%"), ("/robot1", "%robot1"), ("/robot1/cmd_vel", "%robot1%cmd_vel"), ("", "")],
)
def test_mangle_round_trip(plain: str, mangled: str) -> None:
    assert mangle(plain) == mangled
    assert unmangle(mangled) == plain


@pytest.mark.parametrize(
    ("ros", "dds"),
    [
        ("std_msgs/msg/String", "std_msgs::msg::dds_::String_"),
        ("geometry_msgs/msg/Twist", "geometry_msgs::msg::dds_::Twist_"),
        ("example_interfaces/srv/AddTwoInts", "example_interfaces::srv::dds_::AddTwoInts_"),
        (
            "example_interfaces/action/Fibonacci_SendGoal",
            "example_interfaces::action::dds_::Fibonacci_SendGoal_",
        ),
        ("action_msgs/msg/GoalStatusArray", "action_msgs::msg::dds_::GoalStatusArray_"),
        ("irobot_create_msgs/msg/IrIntensityVector", "irobot_create_msgs::msg::dds_::IrIntensityVector_"),
    ],
)
def test_dds_type_name_round_trip(ros: str, dds: str) -> None:
    assert dds_type_name(ros) == dds
    assert ros_type_name(dds) == ros


@pytest.mark.parametrize(
    ("dds", "ros", "key_type"),
    [
        (
            "example_interfaces::srv::dds_::AddTwoInts_Request_",
            "example_interfaces/srv/AddTwoInts",
            "example_interfaces::srv::dds_::AddTwoInts_",
        ),
        (
            "example_interfaces::srv::dds_::AddTwoInts_Response_",
            "example_interfaces/srv/AddTwoInts",
            "example_interfaces::srv::dds_::AddTwoInts_",
        ),
        ("my_pkg::srv::dds_::Request_Request_", "my_pkg/srv/Request", "my_pkg::srv::dds_::Request_"),
        (
            "example_interfaces::srv::dds_::AddTwoInts_Event_",
            "example_interfaces/srv/AddTwoInts_Event",
            "example_interfaces::srv::dds_::AddTwoInts_Event_",
        ),
    ],
)
def test_service_request_type_cut(dds: str, ros: str, key_type: str) -> None:
    assert ros_type_name(dds) == ros
    assert service_key_type(dds) == key_type


@pytest.mark.parametrize(
    "bad",
    ["std_msgs/String", "std_msgs/foo/String", "std_msgs/msg/", "1pkg/msg/X", "a/msg/B/C", ""],
)
def test_dds_type_name_rejects(bad: str) -> None:
    with pytest.raises(InvalidNameError):
        dds_type_name(bad)


@pytest.mark.parametrize(
    "bad",
    [
        "std_msgs::msg::String_",
        "std_msgs::msg::dds_::String",
        "std_msgs::foo::dds_::String_",
        "std_msgs::msg::dds_::_",
        "a::b",
        "",
    ],
)
def test_ros_type_name_rejects(bad: str) -> None:
    with pytest.raises(InvalidNameError):
        ros_type_name(bad)


@pytest.mark.parametrize(
    ("name", "ok"),
    [
        ("/chatter", True),
        ("/robot1/cmd_vel", True),
        ("/_private/x_1", True),
        ("chatter", False),
        ("/", False),
        ("/a//b", False),
        ("/a/", False),
        ("/1abc", False),
        ("/a-b", False),
        ("/a b", False),
        ("/a/%b", False),
        ("/a/{node}", False),
        ("", False),
    ],
)
def test_validate_topic(name: str, ok: bool) -> None:
    if ok:
        assert validate_topic(name) == name
    else:
        with pytest.raises(InvalidNameError) as info:
            validate_topic(name)
        assert info.value.name == name


@pytest.mark.parametrize(
    ("ns", "ok"),
    [("/", True), ("/tb4_01", True), ("/a/b", True), ("a", False), ("/a/", False), ("//", False)],
)
def test_validate_namespace(ns: str, ok: bool) -> None:
    if ok:
        assert validate_namespace(ns) == ns
    else:
        with pytest.raises(InvalidNameError):
            validate_namespace(ns)


@pytest.mark.parametrize(
    ("name", "ns", "node", "fqn"),
    [
        ("odom", "/", None, "/odom"),
        ("odom", "/tb4_01", None, "/tb4_01/odom"),
        ("/abs/odom", "/tb4_01", None, "/abs/odom"),
        ("~/status", "/tb4_01", "sim", "/tb4_01/sim/status"),
        ("~", "/", "sim", "/sim"),
        ("a/b", "/x", None, "/x/a/b"),
    ],
)
def test_resolve_topic(name: str, ns: str, node: str | None, fqn: str) -> None:
    assert resolve_topic(name, ns, node) == fqn


def test_private_name_needs_node() -> None:
    with pytest.raises(InvalidNameError):
        resolve_topic("~/x", "/ns")


@pytest.mark.parametrize(("ns", "seg"), [("/", None), ("/tb4_07", "tb4_07"), ("/tb4_07/sensors", "tb4_07")])
def test_first_segment(ns: str, seg: str | None) -> None:
    assert first_segment(ns) == seg


@pytest.mark.parametrize(
    ("domain", "topic", "typename", "type_hash", "key"),
    [
        (
            0,
            "/chatter",
            "std_msgs/msg/String",
            STRING_HASH,
            f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}",
        ),
        (
            0,
            "/robot1/cmd_vel",
            "geometry_msgs/msg/Twist",
            TWIST_HASH,
            f"0/robot1/cmd_vel/geometry_msgs::msg::dds_::Twist_/{TWIST_HASH}",
        ),
        (
            2,
            "/add_two_ints",
            "example_interfaces/srv/AddTwoInts",
            ADD_TWO_INTS_HASH,
            f"2/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/{ADD_TWO_INTS_HASH}",
        ),
        (
            0,
            "/chatter",
            "std_msgs/msg/String",
            "TypeHashNotSupported",
            "0/chatter/std_msgs::msg::dds_::String_/TypeHashNotSupported",
        ),
    ],
)
def test_data_key_vectors(domain: int, topic: str, typename: str, type_hash: str, key: str) -> None:
    assert data_key(domain, topic, typename, type_hash) == key
    parsed = parse_data_key(key)
    assert parsed == DataKey(domain, topic, key.split("/")[-2], typename, type_hash)
    assert str(parsed) == key


@pytest.mark.parametrize(
    ("typename", "type_hash", "expr"),
    [
        (None, None, "0/tb4_01/odom/*/*"),
        ("nav_msgs/msg/Odometry", None, "0/tb4_01/odom/nav_msgs::msg::dds_::Odometry_/*"),
        ("std_msgs/msg/String", STRING_HASH, f"0/tb4_01/odom/std_msgs::msg::dds_::String_/{STRING_HASH}"),
    ],
)
def test_data_key_expr(typename: str | None, type_hash: str | None, expr: str) -> None:
    assert data_key_expr(0, "/tb4_01/odom", typename, type_hash) == expr


@pytest.mark.parametrize(
    ("key", "reason"),
    [
        ("0/chatter/std_msgs::msg::dds_::String_", "at least 4 chunks"),
        ("x/chatter/std_msgs::msg::dds_::String_/TypeHashNotSupported", "domain"),
        ("-1/chatter/std_msgs::msg::dds_::String_/TypeHashNotSupported", "domain"),
        ("0/chatter/std_msgs/msg/String/TypeHashNotSupported", "DDS type"),
        ("0/chatter/std_msgs::msg::dds_::String_/RIHS01_abc", "hash"),
        ("0/chatter/std_msgs::msg::dds_::String_/nohash", "hash"),
        ("0/1chatter/std_msgs::msg::dds_::String_/TypeHashNotSupported", "digit"),
        ("0/chatter/std_msgs::msg::dds_::String_/TypeHashNotSupported/@adv", "characters"),
    ],
)
def test_parse_data_key_rejects(key: str, reason: str) -> None:
    with pytest.raises(KeyParseError, match=reason) as info:
        parse_data_key(key)
    assert info.value.key == key


@pytest.mark.parametrize(
    ("text", "ok"),
    [
        (STRING_HASH, True),
        ("TypeHashNotSupported", True),
        ("RIHS02_00ff", True),
        ("RIHS01_" + STRING_HASH[7:].upper(), False),
        ("RIHS01_" + "0" * 63, False),
        ("typehashnotsupported", False),
        ("", False),
    ],
)
def test_is_valid_type_hash(text: str, ok: bool) -> None:
    assert is_valid_type_hash(text) is ok


def test_data_key_rejects_bad_hash_and_domain() -> None:
    with pytest.raises(InvalidNameError):
        data_key(0, "/chatter", "std_msgs/msg/String", "bogus")
    with pytest.raises(InvalidNameError):
        data_key(-1, "/chatter", "std_msgs/msg/String", STRING_HASH)
