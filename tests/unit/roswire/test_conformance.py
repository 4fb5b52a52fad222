"""Wire conformance with published rmw_zenoh values: hashes (via schemas.typehash), data keys,
CDR bytes. Pure: no sockets."""

from __future__ import annotations

import pytest
from rosbags.typesys.store import Typestore

from fleetlink.roswire import cdr
from fleetlink.roswire.names import data_key, parse_data_key
from fleetlink.schemas.typehash import type_hash
from fleetlink.schemas.typestore import load_typestore, types_from_srv

ADD_TWO_INTS_SRV = "int64 a\nint64 b\n---\nint64 sum\n"

PUBLISHED: list[tuple[str, str, int, str]] = [
    (
        "std_msgs/msg/String",
        "/chatter",
        0,
        "0/chatter/std_msgs::msg::dds_::String_/"
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    ),
    (
        "geometry_msgs/msg/Twist",
        "/robot1/cmd_vel",
        0,
        "0/robot1/cmd_vel/geometry_msgs::msg::dds_::Twist_/"
        "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
    ),
    (
        "sensor_msgs/msg/Imu",
        "/imu",
        0,
        "0/imu/sensor_msgs::msg::dds_::Imu_/"
        "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b",
    ),
    (
        "nav_msgs/msg/Odometry",
        "/odom",
        0,
        "0/odom/nav_msgs::msg::dds_::Odometry_/"
        "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    ),
    (
        "example_interfaces/srv/AddTwoInts",
        "/add_two_ints",
        2,
        "2/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/"
        "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a",
    ),
]


@pytest.fixture(scope="module", params=["jazzy", "kilted"])
def store(request: pytest.FixtureRequest) -> tuple[Typestore, str]:
    ts = load_typestore(request.param)
    ts.register(types_from_srv(ADD_TWO_INTS_SRV, "example_interfaces/srv/AddTwoInts"))
    return ts, request.param


@pytest.mark.parametrize(("typename", "topic", "domain", "key"), PUBLISHED, ids=[p[0] for p in PUBLISHED])
def test_published_keys_from_computed_hashes(
    store: tuple[Typestore, str], typename: str, topic: str, domain: int, key: str
) -> None:
    ts, distro = store
    computed = type_hash(ts, typename, distro)  # type: ignore[arg-type]
    assert data_key(domain, topic, typename, computed) == key
    assert parse_data_key(key).ros_type == typename


def test_humble_keys_say_type_hash_not_supported() -> None:
    ts = load_typestore("humble")
    assert data_key(0, "/chatter", "std_msgs/msg/String", type_hash(ts, "std_msgs/msg/String", "humble")) == (
        "0/chatter/std_msgs::msg::dds_::String_/TypeHashNotSupported"
    )


def test_cdr_bytes_match_observed_rmw_zenoh_payloads(store: tuple[Typestore, str]) -> None:
    ts, _ = store
    string = ts.types["std_msgs/msg/String"](data="hello 0")
    raw = bytes(ts.serialize_cdr(string, "std_msgs/msg/String"))
    assert raw == bytes.fromhex("000100000800000068656c6c6f203000")
    assert raw == cdr.encode_string("hello 0")
    assert cdr.decode_string(raw) == "hello 0"
    twist_t = ts.types["geometry_msgs/msg/Twist"]
    vec = ts.types["geometry_msgs/msg/Vector3"]
    twist = twist_t(linear=vec(x=0.5, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.25))
    raw = bytes(ts.serialize_cdr(twist, "geometry_msgs/msg/Twist"))
    assert len(raw) == 52
    assert raw[:4] == cdr.HEADER_LE
    assert raw[4:12] == bytes.fromhex("000000000000e03f")  # 0.5 little-endian


@pytest.mark.parametrize(
    ("payload", "problem"),
    [
        (b"\x00\x01\x00\x00", None),
        (b"\x00\x00\x00\x00abcd", None),
        (b"\x00\x01", "too short"),
        (b"\x01\x01\x00\x00", "not plain CDR"),
        (b"\x00\x07\x00\x00", "not plain CDR"),
        (b"", "too short"),
    ],
)
def test_cdr_header_check(payload: bytes, problem: str | None) -> None:
    found = cdr.header_problem(payload)
    if problem is None:
        assert found is None
    else:
        assert found is not None
        assert problem in found


@pytest.mark.parametrize(
    ("payload", "reason"),
    [
        (b"\x00\x01\x00\x00", "no room"),
        (b"\x00\x01\x00\x00\x09\x00\x00\x00abc\x00", "does not fit"),
        (b"\x00\x01\x00\x00\x03\x00\x00\x00abc", "NUL"),
        (b"\x00\x01\x00\x00\x00\x00\x00\x00", "length 0"),
        (b"\x7f\x01\x00\x00\x01\x00\x00\x00\x00", "plain CDR"),
    ],
)
def test_decode_string_rejects(payload: bytes, reason: str) -> None:
    with pytest.raises(ValueError, match=reason):
        cdr.decode_string(payload)


def test_decode_big_endian_string() -> None:
    assert cdr.decode_string(b"\x00\x00\x00\x00\x00\x00\x00\x03hi\x00") == "hi"
