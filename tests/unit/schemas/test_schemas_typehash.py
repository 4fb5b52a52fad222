"""RIHS01 hashes against the vectors published for rmw_zenoh (docs/rmw_zenoh.md section 7)."""

from __future__ import annotations

import pytest
from rosbags.typesys.store import Typestore

from fleetlink.schemas.errors import UnknownTypeError
from fleetlink.schemas.typehash import HUMBLE_HASH, type_description, type_hash
from fleetlink.schemas.typestore import load_typestore, types_from_msg, types_from_srv

ADD_TWO_INTS = "int64 a\nint64 b\n---\nint64 sum\n"


@pytest.fixture(scope="module")
def jazzy() -> Typestore:
    ts = load_typestore("jazzy")
    ts.register(types_from_srv(ADD_TWO_INTS, "example_interfaces/srv/AddTwoInts"))
    return ts


PUBLISHED = [
    ("std_msgs/msg/String", "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"),
    ("geometry_msgs/msg/Twist", "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"),
    ("sensor_msgs/msg/Imu", "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b"),
    ("nav_msgs/msg/Odometry", "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"),
    (
        "example_interfaces/srv/AddTwoInts",
        "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a",
    ),
]


@pytest.mark.parametrize(("typename", "expected"), PUBLISHED)
def test_published_vectors(jazzy: Typestore, typename: str, expected: str) -> None:
    assert type_hash(jazzy, typename, "jazzy") == expected


@pytest.mark.parametrize(("typename", "expected"), PUBLISHED[:4])
def test_same_hash_in_kilted(typename: str, expected: str) -> None:
    assert type_hash(load_typestore("kilted"), typename, "kilted") == expected


@pytest.mark.parametrize(
    ("typename", "prefix"),
    [
        ("std_msgs/msg/Header", "RIHS01_f49fb3ae"),
        ("sensor_msgs/msg/LaserScan", "RIHS01_64c19139"),
        ("tf2_msgs/msg/TFMessage", "RIHS01_e369d0f0"),
        # char maps to uint8 (rosidl_adapter), so this differs from FieldType CHAR's value.
        ("std_msgs/msg/Char", "RIHS01_3ad2d04d"),
    ],
)
def test_known_prefixes(jazzy: Typestore, typename: str, prefix: str) -> None:
    assert type_hash(jazzy, typename, "jazzy").startswith(prefix)


def _uses_char(ts: Typestore, name: str) -> bool:
    desc = type_description(ts, name)
    structs = [desc["type_description"], *desc["referenced_type_descriptions"]]
    return any("'char'" in repr(ts.fielddefs[s["type_name"]][1]) for s in structs)


def test_matches_rosbags_for_types_without_char(jazzy: Typestore) -> None:
    # rosbags' own calculator maps char to FieldType CHAR; for every other type both agree.
    names = [n for n in jazzy.fielddefs if "/srv/" not in n and not _uses_char(jazzy, n)]
    assert len(names) > 150
    for name in names:
        assert type_hash(jazzy, name, "jazzy") == jazzy.hash_rihs01(name), name


def test_char_types_differ_from_rosbags(jazzy: Typestore) -> None:
    names = [n for n in jazzy.fielddefs if "/srv/" not in n and _uses_char(jazzy, n)]
    assert "std_msgs/msg/Char" in names
    for name in names:
        assert type_hash(jazzy, name, "jazzy") != jazzy.hash_rihs01(name), name


def test_humble_has_no_hashes() -> None:
    assert type_hash(load_typestore("humble"), "sensor_msgs/msg/Imu", "humble") == HUMBLE_HASH


@pytest.mark.parametrize("distro", ["humble", "jazzy"])
def test_unknown_type_is_an_error(distro: str) -> None:
    ts = load_typestore("jazzy")
    with pytest.raises(UnknownTypeError) as info:
        type_hash(ts, "nope_msgs/msg/Missing", "jazzy" if distro == "jazzy" else "humble")
    assert info.value.typename == "nope_msgs/msg/Missing"


def test_missing_nested_type_is_named() -> None:
    ts = Typestore()
    ts.register(types_from_msg("other_msgs/Thing thing\n", "my_msgs/msg/Outer"))
    with pytest.raises(UnknownTypeError) as info:
        type_hash(ts, "my_msgs/msg/Outer", "jazzy")
    assert info.value.typename == "other_msgs/msg/Thing"
    assert info.value.referenced_by == "my_msgs/msg/Outer.thing"


def test_service_description_composition(jazzy: Typestore) -> None:
    desc = type_description(jazzy, "example_interfaces/srv/AddTwoInts")
    top = desc["type_description"]
    assert [f["name"] for f in top["fields"]] == ["request_message", "response_message", "event_message"]
    names = [t["type_name"] for t in desc["referenced_type_descriptions"]]
    assert names == sorted(names)
    assert names == [
        "builtin_interfaces/msg/Time",
        "example_interfaces/srv/AddTwoInts_Event",
        "example_interfaces/srv/AddTwoInts_Request",
        "example_interfaces/srv/AddTwoInts_Response",
        "service_msgs/msg/ServiceEventInfo",
    ]
    event = desc["referenced_type_descriptions"][1]
    assert event["fields"][1]["type"] == {
        "type_id": 97,
        "capacity": 1,
        "string_capacity": 0,
        "nested_type_name": "example_interfaces/srv/AddTwoInts_Request",
    }
    info = desc["referenced_type_descriptions"][4]
    gid = next(f for f in info["fields"] if f["name"] == "client_gid")
    assert gid["type"]["type_id"] == 3 + 48  # char[16] -> uint8[16]


@pytest.mark.parametrize(
    ("definition", "type_id", "capacity", "string_capacity"),
    [
        ("bool x", 15, 0, 0),
        ("byte x", 16, 0, 0),
        ("char x", 3, 0, 0),
        ("float32 x", 10, 0, 0),
        ("float64[] x", 11 + 144, 0, 0),
        ("int32[4] x", 6 + 48, 4, 0),
        ("uint16[<=7] x", 5 + 96, 7, 0),
        ("string x", 17, 0, 0),
        ("string<=10 x", 21, 0, 10),
        ("string<=5[<=3] x", 21 + 96, 3, 5),
        ("builtin_interfaces/Time[2] x", 1 + 48, 2, 0),
    ],
)
def test_field_type_ids(definition: str, type_id: int, capacity: int, string_capacity: int) -> None:
    ts = load_typestore("jazzy")
    ts.register(types_from_msg(definition + "\nint32 CONST=3\n", "t_msgs/msg/T"))
    field = type_description(ts, "t_msgs/msg/T")["type_description"]["fields"]
    assert len(field) == 1  # constants are not fields
    assert field[0]["type"]["type_id"] == type_id
    assert field[0]["type"]["capacity"] == capacity
    assert field[0]["type"]["string_capacity"] == string_capacity


def test_empty_message_gets_placeholder_member() -> None:
    ts = load_typestore("jazzy")
    ts.register(types_from_msg("# nothing\n", "t_msgs/msg/Nothing"))
    fields = type_description(ts, "t_msgs/msg/Nothing")["type_description"]["fields"]
    assert [f["name"] for f in fields] == ["structure_needs_at_least_one_member"]
    empty = type_description(ts, "std_msgs/msg/Empty")["type_description"]["fields"]
    assert fields == empty
