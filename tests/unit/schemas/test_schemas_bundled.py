"""The interface packages fleetlink ships: loaded without ``--msg-path``, hashes as published.

Reference hashes (Jazzy). Each is the type hash rmw_zenoh puts in its keys, as found in public
code on GitHub that talks to real ROS 2 nodes; each value was seen in at least two unrelated
projects unless noted:

* ``std_srvs/srv/Trigger``: the key of an ESP32 device's Trigger service in a zenoh test script;
* ``example_interfaces/srv/SetBool``: the key of a Nucleo board's ``set_led`` service (Jazzy);
* ``example_interfaces/srv/AddTwoInts``: docs/reference/rmw_zenoh.md section 7 (rmw_zenoh's own
  test vectors);
* ``example_interfaces/action/Fibonacci_*``, ``action_msgs/srv/CancelGoal``,
  ``action_msgs/msg/GoalStatusArray``: several ROS 2 client libraries' action tests, one
  quoting ``ros2 action info -t`` output and one the installed ``CancelGoal.json``;
* ``rcl_interfaces/srv/*Parameters*``: parameter-service tables of several rmw_zenoh clients
  (one labelled "rcl_interfaces, Jazzy", one taken from the installed ``srv/*.json``).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from rosbags.typesys.store import Typestore

from fleetlink.schemas.bundled import BUNDLED, NOT_IN_HUMBLE, bundled_packages
from fleetlink.schemas.errors import TypeDefinitionError
from fleetlink.schemas.typehash import type_hash
from fleetlink.schemas.typestore import load_typestore, message_types, types_from_action

PUBLISHED_JAZZY = {
    "std_srvs/srv/Trigger": "eeff2cd6fa5ad9d27cdf4dec64818317839b62f212a91e6b5304b634b2062c5f",
    "example_interfaces/srv/SetBool": "a69782e5631b12e15c8e218410de1685bbf13e382718295adad14037a24afbe8",
    "example_interfaces/srv/AddTwoInts": "e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a",
    "example_interfaces/action/Fibonacci_Goal": (
        "226cb437e4355dcd3e914f930382a3b0cc1da81545bd319ed554e95a03255f51"
    ),
    "example_interfaces/action/Fibonacci_SendGoal": (
        "d1a57fb2a4afe8c21e34fb10db206f16ce6729b28531141472df92277c55b557"
    ),
    "example_interfaces/action/Fibonacci_GetResult": (
        "1b0de0d5d29dc955d92f546706568428632771db13ec84c15ec1c1a59f424a57"
    ),
    "example_interfaces/action/Fibonacci_FeedbackMessage": (
        "c1de71afd52e49a89c53d8262366884185bc0a02f78ce051c4e46b0a7fe59bb2"
    ),
    "action_msgs/srv/CancelGoal": "573d8b0a534451d7bc2ac8c5ffde8ac14b8593b7001175d0cd6516dcbeb8689a",
    "action_msgs/msg/GoalStatusArray": "6c1684b00f177d37438febe6e709fc4e2b0d4248dca4854946f9ed8b30cda83e",
    "rcl_interfaces/srv/GetParameters": "bf9803d5c74cf989a5de3e0c2e99444599a627c7ff75f97b8c05b01003675cbc",
    "rcl_interfaces/srv/ListParameters": "3e6062bfbb27bfb8730d4cef2558221f51a11646d78e7bb30a1e83afac3aad9d",
    "rcl_interfaces/srv/GetParameterTypes": (
        "da199c878688b3e530bdfe3ca8f74cb9fa0c303101e980a9e8f260e25e1c80ca"
    ),
    "rcl_interfaces/srv/SetParameters": "56eed9a67e169f9cb6c1f987bc88f868c14a8fc9f743a263bc734c154015d7e0",
    "rcl_interfaces/srv/SetParametersAtomically": (
        "0e192ef259c07fc3c07a13191d27002222e65e00ccec653ca05e856f79285fcd"
    ),
}


@pytest.fixture(scope="module")
def jazzy() -> Typestore:
    return load_typestore("jazzy")  # no msg paths: the bundled packages only


@pytest.mark.parametrize(("typename", "digest"), PUBLISHED_JAZZY.items(), ids=list(PUBLISHED_JAZZY))
def test_published_hashes_without_msg_path(jazzy: Typestore, typename: str, digest: str) -> None:
    assert type_hash(jazzy, typename, "jazzy") == f"RIHS01_{digest}"


def test_every_bundled_package_has_its_licence_and_manifest() -> None:
    packages = bundled_packages()
    assert {"std_srvs", "example_interfaces", "action_msgs", "unique_identifier_msgs"} <= set(packages)
    readme = (BUNDLED / "README.md").read_text()
    for name, folder in packages.items():
        assert (folder / "LICENSE").is_file(), name
        assert f"<name>{name}</name>" in (folder / "package.xml").read_text(), name
        assert f"`{name}/`" in readme, f"{name} has no source note in schemas/msgs/README.md"


@pytest.mark.parametrize("distro", ["humble", "jazzy", "kilted"])
def test_every_service_and_action_loads_in_every_distro(distro: str) -> None:
    ts = load_typestore(distro)  # type: ignore[arg-type]
    names = set(message_types(ts))
    for folder in bundled_packages().values():
        for path in folder.glob("srv/*.srv"):
            interface = f"{folder.name}/srv/{path.stem}"
            expected = not (distro == "humble" and interface in NOT_IN_HUMBLE)
            assert (f"{interface}_Request" in names) is expected, interface
        for path in folder.glob("action/*.action"):
            for part in ("Goal", "Result", "Feedback", "FeedbackMessage", "SendGoal_Request"):
                assert f"{folder.name}/action/{path.stem}_{part}" in names


def test_humble_has_no_type_description_service() -> None:
    ts = load_typestore("humble")
    assert "type_description_interfaces/srv/GetTypeDescription_Request" not in ts.fielddefs
    assert "std_srvs/srv/Trigger_Request" in ts.fielddefs


def test_a_package_given_replaces_the_bundled_one(tmp_path: Path) -> None:
    own = tmp_path / "std_srvs"
    (own / "srv").mkdir(parents=True)
    (own / "srv" / "Ping.srv").write_text("---\nbool ok\n")
    names = message_types(load_typestore("jazzy", [own]))
    assert "std_srvs/srv/Ping_Request" in names
    assert "std_srvs/srv/Trigger_Request" not in names  # the bundled package was left out
    assert "example_interfaces/srv/Trigger_Request" in names  # the others stay


def test_bundled_packages_can_be_left_out() -> None:
    assert "std_srvs/srv/Trigger_Request" not in load_typestore("jazzy", bundled=False).fielddefs


def test_action_messages_are_the_ones_rosidl_makes() -> None:
    types = types_from_action("int32 order\n---\nint32[] sequence\n---\nint32[] partial\n", "p/action/F")
    fields = {name: [f for f, _ in defs[1]] for name, defs in types.items()}
    assert fields == {
        "p/action/F_Goal": ["order"],
        "p/action/F_Result": ["sequence"],
        "p/action/F_Feedback": ["partial"],
        "p/action/F_SendGoal_Request": ["goal_id", "goal"],
        "p/action/F_SendGoal_Response": ["accepted", "stamp"],
        "p/action/F_GetResult_Request": ["goal_id"],
        "p/action/F_GetResult_Response": ["status", "result"],
        "p/action/F_FeedbackMessage": ["goal_id", "feedback"],
    }


def test_an_action_needs_three_parts() -> None:
    with pytest.raises(TypeDefinitionError, match="two '---'"):
        types_from_action("int32 a\n---\nint32 b\n", "p/action/F")


def test_a_folder_of_packages_is_named_as_such() -> None:
    with pytest.raises(TypeDefinitionError, match="give each package's folder"):
        load_typestore("jazzy", [BUNDLED])
