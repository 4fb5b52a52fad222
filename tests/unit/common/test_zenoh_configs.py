"""Router templates in deploy/zenoh: placeholders, generated ACL parts, and every file parses."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import zenoh

from fleetlink.common.errors import ConfigError
from fleetlink.common.zenoh_configs import (
    ALL_MESSAGES,
    RouterConfigError,
    cloud_site_acl,
    edge_raw_acl,
    placeholders,
    render_router_config,
    render_router_json5,
    render_text,
    uncovered_raw_keys,
)
from tests.paths import DEPLOY as DEPLOY_ROOT

DEPLOY = DEPLOY_ROOT / "zenoh"
TEMPLATES = sorted(DEPLOY.glob("*.json5"))

# Values for every built-in placeholder; a template may ignore some of them.
RENDER_ARGS: dict[str, Any] = {
    "site": "site-a",
    "listen": ["tcp/127.0.0.1:7447"],
    "connect": ["tls/127.0.0.1:7448"],
    "cert_dir": "/etc/fleetlink/certs",
}


def acl(conf: zenoh.Config) -> dict[str, Any]:
    value: dict[str, Any] = json.loads(conf.get_json("access_control"))
    return value


def rule(conf: zenoh.Config, rule_id: str) -> dict[str, Any]:
    for entry in acl(conf)["rules"]:
        if entry["id"] == rule_id:
            return dict(entry)
    raise KeyError(rule_id)


def get(conf: zenoh.Config, key: str) -> Any:
    return json.loads(conf.get_json(key))


# --- the shipped files -----------------------------------------------------------------------


def test_deploy_has_the_four_templates() -> None:
    assert [p.name for p in TEMPLATES] == [
        "cloud-router-dev.json5",
        "cloud-router.json5",
        "edge-router-dev.json5",
        "edge-router.json5",
    ]


@pytest.mark.parametrize("path", TEMPLATES, ids=lambda p: p.name)
def test_every_template_parses_after_rendering(path: Path) -> None:
    sites = ["site-a", "site-b"] if path.name.startswith("cloud") else []
    conf = render_router_config(path, sites=sites, **RENDER_ARGS)
    assert get(conf, "mode") == "router"
    assert get(conf, "listen/endpoints") == RENDER_ARGS["listen"]
    assert get(conf, "connect/endpoints") == RENDER_ARGS["connect"]
    # The file itself is valid JSON5 for zenoh only once rendered: its placeholders are strings
    # where zenoh expects lists, so the raw file must be refused (nobody runs it unrendered).
    with pytest.raises(zenoh.ZError):
        zenoh.Config.from_file(str(path))


@pytest.mark.parametrize(
    ("path", "names"),
    [
        ("edge-router.json5", {"SITE", "LISTEN", "CONNECT", "CERT_DIR"}),
        ("cloud-router.json5", {"LISTEN", "CONNECT", "CERT_DIR"}),
        ("edge-router-dev.json5", {"SITE", "LISTEN", "CONNECT"}),
        ("cloud-router-dev.json5", {"LISTEN", "CONNECT"}),
    ],
)
def test_templates_use_only_builtin_placeholders(path: str, names: set[str]) -> None:
    assert placeholders((DEPLOY / path).read_text()) == names


@pytest.mark.parametrize(
    ("path", "key", "expected"),
    [
        ("cloud-router.json5", "transport/link/tls/enable_mtls", True),
        ("cloud-router.json5", "transport/link/protocols", ["tls"]),
        (
            "cloud-router.json5",
            "transport/link/tls/listen_private_key",
            "/etc/fleetlink/certs/fleetlink-cloud-key.pem",
        ),
        ("cloud-router.json5", "access_control/enabled", True),
        ("cloud-router.json5", "access_control/default_permission", "deny"),
        ("cloud-router.json5", "scouting/gossip/enabled", False),
        ("edge-router.json5", "transport/link/tls/enable_mtls", True),
        ("edge-router.json5", "transport/link/tls/verify_name_on_connect", True),
        (
            "edge-router.json5",
            "transport/link/tls/connect_certificate",
            "/etc/fleetlink/certs/edge-site-a.pem",
        ),
        (
            "edge-router.json5",
            "transport/link/tls/connect_private_key",
            "/etc/fleetlink/certs/edge-site-a-key.pem",
        ),
        ("edge-router.json5", "access_control/default_permission", "deny"),
        ("edge-router.json5", "connect/exit_on_failure", False),
        ("cloud-router-dev.json5", "access_control/default_permission", "deny"),
        ("edge-router-dev.json5", "access_control/enabled", False),
    ],
)
def test_security_settings_of_the_templates(path: str, key: str, expected: object) -> None:
    sites = ["site-a"] if path.startswith("cloud") else []
    conf = render_router_config(DEPLOY / path, sites=sites, **RENDER_ARGS)
    assert get(conf, key) == expected


def test_edge_wan_rules_are_scoped_to_the_site() -> None:
    conf = render_router_config(DEPLOY / "edge-router.json5", **RENDER_ARGS)
    assert rule(conf, "wan-site")["key_exprs"] == ["fleetlink/site-a/**"]
    interest = rule(conf, "wan-cloud-interest")
    assert interest["flows"] == ["ingress"]
    assert not {"put", "delete", "reply"} & set(interest["messages"])
    subjects = {s["id"]: s for s in acl(conf)["subjects"]}
    assert subjects["cloud"]["cert_common_names"] == ["fleetlink-cloud"]
    assert "tls" not in subjects["site-network"]["link_protocols"]


def test_edge_downsampling_applies_to_wan_egress_only() -> None:
    conf = render_router_config(DEPLOY / "edge-router.json5", **RENDER_ARGS)
    [item] = get(conf, "downsampling")
    assert item["flows"] == ["egress"]
    assert item["link_protocols"] == ["tls", "quic"]
    assert {r["key_expr"]: r["freq"] for r in item["rules"]}["*/**/imu/**"] == 5.0


# --- placeholders ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ('{a: "${X}"}', {"X"}),
        ('{a: "k/${SITE}/**", b: "${CERT_DIR}/${SITE}.pem"}', {"SITE", "CERT_DIR"}),
        ("{a: '${X_1}'}", {"X_1"}),
        ('// "${IN_COMMENT}"\n{a: 1}', set()),
        ('/* "${BLOCK}" */ {a: "x"}', set()),
        ('{a: "${lower}", b: "$X", c: "{Y}"}', set()),
    ],
)
def test_placeholders(text: str, expected: set[str]) -> None:
    assert placeholders(text) == expected


@pytest.mark.parametrize(
    ("text", "values", "expected"),
    [
        ('{e: "${L}"}', {"L": ["tcp/a:1", "tls/b:2"]}, '{e: ["tcp/a:1", "tls/b:2"]}'),
        ('{e: "${L}"}', {"L": []}, "{e: []}"),
        ('{e: "${S}"}', {"S": "x"}, '{e: "x"}'),
        ('{k: "fleetlink/${S}/**"}', {"S": "site-a"}, '{k: "fleetlink/site-a/**"}'),
        ('{k: "${D}/${S}.pem"}', {"D": "/c", "S": "e"}, '{k: "/c/e.pem"}'),
        ('{k: "${D}/ca.pem"}', {"D": 'C:\\certs "x"'}, '{k: "C:\\\\certs \\"x\\"/ca.pem"}'),
        ("{k: '${S}'}", {"S": "v"}, '{k: "v"}'),
        ('// "${S}" stays\n{k: 1}', {"S": "v"}, '// "${S}" stays\n{k: 1}'),
        ('{k: "\\"${S}\\""}', {"S": "v"}, '{k: "\\"v\\""}'),
        ('{k: "${S}", unused: 1}', {"S": "v", "OTHER": "w"}, '{k: "v", unused: 1}'),
    ],
)
def test_render_text(text: str, values: dict[str, Any], expected: str) -> None:
    assert render_text(text, values) == expected


@pytest.mark.parametrize(
    ("text", "values", "message"),
    [
        ('{a: "${X}", b: "${Y}"}', {}, "no value for placeholder(s) ${X}, ${Y}"),
        ('{a: "k/${L}"}', {"L": ["a", "b"]}, "must be a string"),
    ],
)
def test_render_text_errors(text: str, values: dict[str, Any], message: str) -> None:
    with pytest.raises(
        RouterConfigError, match=message.replace("$", r"\$").replace("(", r"\(").replace(")", r"\)")
    ) as info:
        render_text(text, values, source="t.json5")
    assert str(info.value).startswith("t.json5: ")
    assert isinstance(info.value, ConfigError)


# --- generated ACL parts ---------------------------------------------------------------------


def test_cloud_site_acl_scopes_one_site() -> None:
    block = cloud_site_acl("site-a")
    assert block.subjects == [{"id": "site-site-a", "cert_common_names": ["edge-site-a"]}]
    by_id = {r["id"]: r for r in block.rules}
    assert by_id["site-site-a-in"] == {
        "id": "site-site-a-in",
        "permission": "allow",
        "flows": ["ingress"],
        "messages": list(ALL_MESSAGES),
        "key_exprs": ["fleetlink/site-a/**"],
    }
    assert by_id["site-site-a-out"]["key_exprs"] == ["fleetlink/site-a/**"]
    assert set(by_id["site-site-a-out"]["messages"]) == {"put", "delete", "reply", "liveliness_token"}
    # Declarations and queries towards the edge may use wildcards across sites, data may not.
    assert by_id["site-site-a-out-interest"]["key_exprs"] == ["fleetlink/**"]
    assert not {"put", "delete", "reply"} & set(by_id["site-site-a-out-interest"]["messages"])
    assert block.policies == [{"id": "site-site-a", "rules": list(by_id), "subjects": ["site-site-a"]}]


def test_cloud_site_acl_with_raw_topics() -> None:
    block = cloud_site_acl("b", raw_keys=["0/robot1/imu/**"])
    by_id = {r["id"]: r for r in block.rules}
    assert by_id["site-b-raw-in"]["messages"] == ["put", "delete"]
    assert by_id["site-b-raw-in"]["flows"] == ["ingress"]
    assert by_id["site-b-raw-out-interest"]["messages"] == ["declare_subscriber"]


@pytest.mark.parametrize("site", ["", "a/b", "*", "site a", "-x", "@x", "a" * 59, "$*"])
def test_cloud_site_acl_rejects_bad_site_names(site: str) -> None:
    with pytest.raises(RouterConfigError, match="site name"):
        cloud_site_acl(site)


@pytest.mark.parametrize("key", ["fleetlink/site-a/**", "**", "@ros2_lv/**", "a//b", "a/*x"])
def test_raw_keys_must_be_raw_and_valid(key: str) -> None:
    with pytest.raises(RouterConfigError, match="raw_to_cloud"):
        edge_raw_acl([key])


@pytest.mark.parametrize(
    ("keys", "uncovered"),
    [
        (["0/robot1/imu/data/**"], []),
        (["0/imu/data/sensor_msgs::msg::dds_::Imu_/RIHS01_00"], []),
        (["*/**/imu/**"], []),
        (["0/robot1/odom/**", "0/robot1/cmd_vel/**"], ["0/robot1/cmd_vel/**"]),
        (["**"], ["**"]),
    ],
)
def test_uncovered_raw_keys_against_the_edge_rules(keys: list[str], uncovered: list[str]) -> None:
    conf = render_router_config(DEPLOY / "edge-router.json5", **RENDER_ARGS)
    assert uncovered_raw_keys(keys, get(conf, "downsampling")) == uncovered


@pytest.mark.parametrize(
    ("downsampling", "uncovered"),
    [
        ([{"flows": ["ingress"], "messages": ["put"], "rules": [{"key_expr": "0/**", "freq": 1}]}], ["0/a"]),
        ([{"messages": ["delete"], "rules": [{"key_expr": "0/**", "freq": 1}]}], ["0/a"]),
        ([{"messages": ["put"], "rules": [{"key_expr": "0/**", "freq": 1}]}], []),
        ([], ["0/a"]),
    ],
)
def test_uncovered_raw_keys_needs_egress_put_rules(
    downsampling: list[dict[str, Any]], uncovered: list[str]
) -> None:
    assert uncovered_raw_keys(["0/a"], downsampling) == uncovered


# --- rendering with generated parts ----------------------------------------------------------


def test_cloud_render_appends_one_block_per_site() -> None:
    conf = render_router_config(DEPLOY / "cloud-router.json5", sites=["a", "b"], **RENDER_ARGS)
    policies = {p["id"]: p for p in acl(conf)["policies"]}
    assert set(policies) == {"services", "site-a", "site-b"}
    assert rule(conf, "site-b-in")["key_exprs"] == ["fleetlink/b/**"]


def test_cloud_render_raw_from_opens_raw_keys_to_services() -> None:
    conf = render_router_config(
        DEPLOY / "cloud-router.json5", sites=["a"], raw_from={"a": ["*/**/imu/**"]}, **RENDER_ARGS
    )
    assert rule(conf, "services-raw-out")["key_exprs"] == ["*/**/imu/**"]
    assert {p["id"]: p for p in acl(conf)["policies"]}["services-raw"]["subjects"] == ["services"]


def test_edge_render_raw_to_cloud_adds_wan_rules() -> None:
    conf = render_router_config(DEPLOY / "edge-router.json5", raw_to_cloud=["0/r1/imu/**"], **RENDER_ARGS)
    assert rule(conf, "wan-raw-out") == {
        "id": "wan-raw-out",
        "permission": "allow",
        "flows": ["egress"],
        "messages": ["put", "delete"],
        "key_exprs": ["0/r1/imu/**"],
    }


@pytest.mark.parametrize(
    ("path", "kwargs", "message"),
    [
        ("edge-router.json5", {"raw_to_cloud": ["0/r1/cmd_vel/**"]}, "only cross the WAN downsampled"),
        ("edge-router-dev.json5", {"raw_to_cloud": ["0/r1/imu/**"]}, "only cross the WAN downsampled"),
        ("edge-router.json5", {"site": "a/b"}, "site name 'a/b'"),
        ("cloud-router.json5", {"sites": ["a", "a"]}, "duplicate id"),
        ("cloud-router.json5", {"sites": ["a"], "raw_from": {"b": ["0/x"]}}, "missing from sites"),
        ("cloud-router.json5", {"sites": ["a"], "raw_from": {"a": ["fleetlink/a/x"]}}, "not a raw ROS"),
        ("cloud-router-dev.json5", {"listen": ["bogus"]}, "invalid zenoh config after rendering"),
        ("edge-router.json5", {"site": None}, r"no value for placeholder\(s\) \$\{SITE\}"),
    ],
)
def test_render_errors_name_the_file(path: str, kwargs: dict[str, Any], message: str) -> None:
    args = RENDER_ARGS | kwargs
    with pytest.raises(RouterConfigError, match=message) as info:
        render_router_config(DEPLOY / path, **args)
    assert str(info.value).startswith(str(DEPLOY / path))


def test_acl_generated_for_a_config_without_acl_is_refused() -> None:
    text = '{mode: "router", listen: {endpoints: "${LISTEN}"}}'
    with pytest.raises(RouterConfigError, match="access_control is not enabled"):
        render_router_json5(text, sites=["a"])


def test_policy_naming_an_unknown_subject_is_refused() -> None:
    text = json.dumps(
        {
            "access_control": {
                "enabled": True,
                "rules": [{"id": "r", "permission": "allow", "messages": ["put"], "key_exprs": ["a"]}],
                "subjects": [{"id": "s"}],
                "policies": [{"rules": ["r"], "subjects": ["nobody"]}],
            }
        }
    )
    with pytest.raises(RouterConfigError, match=r"unknown subjects \['nobody'\]"):
        render_router_json5(text, sites=["a"])


def test_missing_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(RouterConfigError, match="cannot read router config"):
        render_router_config(tmp_path / "nope.json5")
