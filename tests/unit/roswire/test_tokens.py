"""Liveliness token strings (rmw_zenoh.md §3): build, parse, reject."""

from __future__ import annotations

import pytest

from fleetlink.roswire.errors import InvalidNameError, TokenError
from fleetlink.roswire.qos import DEFAULT, SENSOR_DATA, TRANSIENT_LOCAL, QoS
from fleetlink.roswire.tokens import (
    EndpointInfo,
    EntityKind,
    NodeInfo,
    endpoint_token,
    liveliness_prefix,
    node_token,
    parse_token,
)

ZID = "aac3178e146ba6f1fc6e6a4085e77f21"
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
ADD_HASH = "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"

# Real token keys from rmw_zenoh's design document (domain 2), full hashes.
LISTENER_NN = f"@ros2_lv/2/{ZID}/0/0/NN/%/%/listener"
LISTENER_MS = (
    f"@ros2_lv/2/{ZID}/0/10/MS/%/%/listener/%chatter/std_msgs::msg::dds_::String_/{STRING_HASH}/::,10:,:,:,,"
)
TALKER_MP = (
    "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
    f"std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,"
)
SERVER_SS = (
    "@ros2_lv/2/f9980ee0495eaafb3e38f0d19e2eae12/0/10/SS/%/%/add_two_ints_server/%add_two_ints/"
    f"example_interfaces::srv::dds_::AddTwoInts_/{ADD_HASH}/::,10:,:,:,,"
)


def test_node_token_vector() -> None:
    assert node_token(2, ZID, 0, "/", "listener") == LISTENER_NN
    assert node_token(0, "1f", 3, "/tb4_01/sensors", "imu", enclave="/secure") == (
        "@ros2_lv/0/1f/3/3/NN/%secure/%tb4_01%sensors/imu"
    )


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [
        (
            {
                "domain": 2,
                "zid": ZID,
                "nid": 0,
                "eid": 10,
                "kind": EntityKind.SUBSCRIPTION,
                "namespace": "/",
                "node_name": "listener",
                "topic": "/chatter",
                "typename": "std_msgs/msg/String",
                "type_hash": STRING_HASH,
                "qos": DEFAULT,
            },
            LISTENER_MS,
        ),
        (
            {
                "domain": 2,
                "zid": "8b20917502ee955ac4476e0266340d5c",
                "nid": 0,
                "eid": 10,
                "kind": EntityKind.PUBLISHER,
                "namespace": "/",
                "node_name": "talker",
                "topic": "/chatter",
                "typename": "std_msgs/msg/String",
                "type_hash": STRING_HASH,
                "qos": QoS(depth=7),
            },
            TALKER_MP,
        ),
        (
            {
                "domain": 2,
                "zid": "f9980ee0495eaafb3e38f0d19e2eae12",
                "nid": 0,
                "eid": 10,
                "kind": EntityKind.SERVICE_SERVER,
                "namespace": "/",
                "node_name": "add_two_ints_server",
                "topic": "/add_two_ints",
                "typename": "example_interfaces/srv/AddTwoInts",
                "type_hash": ADD_HASH,
                "qos": DEFAULT,
            },
            SERVER_SS,
        ),
        (
            {
                "domain": 0,
                "zid": "ab",
                "nid": 1,
                "eid": 4,
                "kind": EntityKind.PUBLISHER,
                "namespace": "/tb4_01",
                "node_name": "sim",
                "topic": "/tb4_01/imu",
                "typename": "sensor_msgs/msg/Imu",
                "type_hash": "TypeHashNotSupported",
                "qos": SENSOR_DATA,
            },
            "@ros2_lv/0/ab/1/4/MP/%/%tb4_01/sim/%tb4_01%imu/sensor_msgs::msg::dds_::Imu_/TypeHashNotSupported/"
            "2::,5:,:,:,,",
        ),
        (
            {
                "domain": 0,
                "zid": "ab",
                "nid": 1,
                "eid": 5,
                "kind": EntityKind.PUBLISHER,
                "namespace": "/",
                "node_name": "tf",
                "topic": "/tf_static",
                "typename": "tf2_msgs/msg/TFMessage",
                "type_hash": "TypeHashNotSupported",
                "qos": TRANSIENT_LOCAL,
            },
            "@ros2_lv/0/ab/1/5/MP/%/%/tf/%tf_static/tf2_msgs::msg::dds_::TFMessage_/TypeHashNotSupported/"
            ":1:,1:,:,:,,",
        ),
    ],
)
def test_endpoint_token_vectors(kwargs: dict[str, object], key: str) -> None:
    assert endpoint_token(**kwargs) == key  # type: ignore[arg-type]
    parsed = parse_token(key)
    assert isinstance(parsed, EndpointInfo)
    assert parsed.key == key
    assert (parsed.domain, parsed.zid, parsed.nid, parsed.eid, parsed.kind) == (
        kwargs["domain"],
        kwargs["zid"],
        kwargs["nid"],
        kwargs["eid"],
        kwargs["kind"],
    )
    got = (parsed.namespace, parsed.node_name, parsed.topic, parsed.ros_type, parsed.type_hash, parsed.qos)
    assert got == (
        kwargs["namespace"],
        kwargs["node_name"],
        kwargs["topic"],
        kwargs["typename"],
        kwargs["type_hash"],
        kwargs["qos"],
    )


def test_parse_node_token() -> None:
    node = parse_token(LISTENER_NN)
    assert node == NodeInfo(2, ZID, 0, "/", "/", "listener", LISTENER_NN)
    assert isinstance(node, NodeInfo)
    assert node.fqn == "/listener"
    nested = parse_token("@ros2_lv/0/1f/3/3/NN/%/%tb4_01%sensors/imu")
    assert isinstance(nested, NodeInfo)
    assert nested.fqn == "/tb4_01/sensors/imu"


def test_endpoint_gid_is_hash_of_key() -> None:
    parsed = parse_token(TALKER_MP)
    assert isinstance(parsed, EndpointInfo)
    assert len(parsed.gid) == 16
    assert parsed.gid != parse_token(LISTENER_MS).key.encode()[:16]


def test_endpoint_token_rejects_node_kind_and_bad_names() -> None:
    common = {
        "domain": 0,
        "zid": "ab",
        "nid": 1,
        "eid": 2,
        "namespace": "/",
        "node_name": "n",
        "topic": "/t",
        "typename": "std_msgs/msg/String",
        "type_hash": STRING_HASH,
        "qos": DEFAULT,
    }
    with pytest.raises(TokenError):
        endpoint_token(kind=EntityKind.NODE, **common)  # type: ignore[arg-type]
    with pytest.raises(InvalidNameError):
        endpoint_token(kind=EntityKind.PUBLISHER, **{**common, "topic": "t"})  # type: ignore[arg-type]
    with pytest.raises(InvalidNameError):
        endpoint_token(kind=EntityKind.PUBLISHER, **{**common, "type_hash": "x"})  # type: ignore[arg-type]


BAD_TOKENS: list[tuple[str, str]] = [
    ("@ros2_lv/2/zz/0/0/NN/%/%/listener", "zid"),
    (f"@ros2_lv/2/{ZID}/0/0/NN/%/%", "chunks"),
    (f"@ros2_lv/x/{ZID}/0/0/NN/%/%/listener", "domain"),
    (f"@ros2_lv/2/{ZID}/a/0/NN/%/%/listener", "node id"),
    (f"@ros2_lv/2/{ZID}/0/1/NN/%/%/listener", "differs"),
    (f"@ros2_lv/2/{ZID}/0/0/XX/%/%/listener", "kind"),
    (f"@ros2_lv/2/{ZID}/0/0/NN/%/ns/listener", "namespace"),
    (f"@ros2_lv/2/{ZID}/0/0/NN/%/%/lis-tener", "characters"),
    (f"other/2/{ZID}/0/0/NN/%/%/listener", "@ros2_lv"),
    (LISTENER_MS.replace("/MS/", "/NN/"), "9 chunks"),
    (LISTENER_NN.replace("/NN/", "/MP/"), "13 chunks"),
    (LISTENER_MS.replace("%chatter", "chatter"), "fully qualified"),
    (LISTENER_MS.replace("std_msgs::msg::dds_::String_", "std_msgs::String_"), "DDS type"),
    (LISTENER_MS.replace("std_msgs::msg::dds_::String_", "std_msgs/String"), "14 chunks"),
    (LISTENER_MS.replace(STRING_HASH, "RIHS01_1234"), "hash"),
    (LISTENER_MS.replace("::,10:,:,:,,", "10"), "6 ':'"),
    (LISTENER_MS.replace("::,10:,:,:,,", "::10:,:,:,,"), "history"),
    (LISTENER_MS + "/extra", "chunks"),
    ("", "@ros2_lv"),
]


@pytest.mark.parametrize(("key", "reason"), BAD_TOKENS)
def test_malformed_tokens_raise(key: str, reason: str) -> None:
    with pytest.raises(TokenError, match=reason) as info:
        parse_token(key)
    assert info.value.key == key


def test_liveliness_prefix() -> None:
    assert liveliness_prefix(0) == "@ros2_lv/0/**"
    assert liveliness_prefix(42) == "@ros2_lv/42/**"
