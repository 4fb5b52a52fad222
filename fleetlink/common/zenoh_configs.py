"""Zenoh router configs for fleetlink: JSON5 templates in ``deploy/zenoh/`` made concrete.

The files in ``deploy/zenoh/`` are ordinary zenoh JSON5 configs with ``${NAME}`` placeholders
inside string literals. :func:`render_router_config` fills them in and returns a
``zenoh.Config`` ready for ``zenoh.open``::

    conf = render_router_config(
        "deploy/zenoh/edge-router.json5",
        site="warehouse-a",
        listen=["tcp/0.0.0.0:7447"],
        connect=["tls/cloud.example.com:7447"],
        cert_dir="/etc/fleetlink/certs",
    )

Placeholder rules (only string literals are looked at; comments are left alone):

* a string that is exactly ``"${NAME}"`` is replaced by the JSON form of the value, so a list
  value becomes a JSON array (``listen: { endpoints: "${LISTEN}" }``);
* ``${NAME}`` inside a longer string is replaced by the (string) value, JSON-escaped
  (``"fleetlink/${SITE}/**"``).

Built-in names: ``SITE``, ``LISTEN``, ``CONNECT``, ``CERT_DIR``; an operator's own templates
may use more, filled from ``values``. A placeholder left without a value is an error naming
the file and the placeholder; values a template does not use are ignored, so one call site
can render either the TLS or the dev variant.

Zenoh's ACL cannot bind an identity into a key expression, so the per-site part of the cloud's
ACL is generated: ``sites=["a", "b"]`` appends, for each site, the rules, subjects and policies
that let the edge whose client certificate is named ``edge-<site>`` act on
``fleetlink/<site>/**`` only (:func:`cloud_site_acl`). ``raw_to_cloud`` (edge) and ``raw_from``
(cloud) open the WAN to chosen raw ROS topics; the edge refuses a raw topic that no egress
downsampling rule covers.

Rendered configs may hold secrets (a password); nothing here logs values or rendered text.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zenoh

from fleetlink.common.certs import CertError, check_site_certificate, edge_name
from fleetlink.common.errors import ConfigError
from fleetlink.common.names import site_problem

__all__ = [
    "ALL_MESSAGES",
    "AclBlock",
    "RouterConfigError",
    "cloud_site_acl",
    "concrete_json5",
    "edge_raw_acl",
    "placeholders",
    "render_router_config",
    "render_router_json5",
    "render_text",
    "services_raw_acl",
    "uncovered_raw_keys",
]

Value = str | Sequence[str]

#: Every message kind zenoh's ACL knows (1.x).
ALL_MESSAGES: tuple[str, ...] = (
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "liveliness_query",
    "declare_liveliness_subscriber",
)
_DATA_OUT = ("put", "delete", "reply")
_INTEREST = (
    "declare_subscriber",
    "declare_queryable",
    "query",
    "liveliness_token",
    "liveliness_query",
    "declare_liveliness_subscriber",
)

#: ACL subject ids the templates define: the cloud's own services, the edge's WAN link.
SERVICES_SUBJECT = "services"
WAN_SUBJECT = "cloud"

_NAME = r"[A-Z][A-Z0-9_]*"
_TOKEN_RE = re.compile(
    r'"(?:[^"\\]|\\.)*"'  # double-quoted string
    r"|'(?:[^'\\]|\\.)*'"  # single-quoted string (JSON5)
    r"|//[^\n]*"  # line comment
    r"|/\*.*?\*/",  # block comment
    re.DOTALL,
)
_WHOLE_RE = re.compile(rf"^\$\{{({_NAME})\}}$")
_EMBEDDED_RE = re.compile(rf"\$\{{({_NAME})\}}")


class RouterConfigError(ConfigError):
    """A router template could not be rendered; carries the file and the placeholder or key."""

    def __init__(self, message: str, *, source: str, name: str | None = None) -> None:
        super().__init__(f"{source}: {message}")
        self.source = source
        self.name = name


@dataclass(frozen=True)
class AclBlock:
    """ACL entries to append to a config's ``access_control`` lists."""

    rules: list[dict[str, Any]] = field(default_factory=list)
    subjects: list[dict[str, Any]] = field(default_factory=list)
    policies: list[dict[str, Any]] = field(default_factory=list)

    def __add__(self, other: AclBlock) -> AclBlock:
        return AclBlock(
            [*self.rules, *other.rules],
            [*self.subjects, *other.subjects],
            [*self.policies, *other.policies],
        )


# --- placeholders (pure) ---------------------------------------------------------------------


def _string_body(token: str) -> str | None:
    """The inner text of a string token, or None for a comment."""
    if token[0] in "\"'":
        return token[1:-1]
    return None


def placeholders(text: str) -> frozenset[str]:
    """The placeholder names used in the string literals of a JSON5 text."""
    names: set[str] = set()
    for match in _TOKEN_RE.finditer(text):
        body = _string_body(match.group(0))
        if body is not None:
            names.update(_EMBEDDED_RE.findall(body))
    return frozenset(names)


def _as_json(value: Value) -> str:
    if isinstance(value, str):
        return json.dumps(value)
    return json.dumps(list(value))


def render_text(text: str, values: Mapping[str, Value], *, source: str = "<text>") -> str:
    """Fill in the ``${NAME}`` placeholders of a JSON5 text (see the module docstring)."""
    missing = sorted(placeholders(text) - set(values))
    if missing:
        listed = ", ".join(f"${{{name}}}" for name in missing)
        raise RouterConfigError(f"no value for placeholder(s) {listed}", source=source, name=missing[0])

    def embedded(match: re.Match[str]) -> str:
        name = match.group(1)
        value = values[name]
        if not isinstance(value, str):
            raise RouterConfigError(
                f"placeholder ${{{name}}} is part of a longer string, so its value must be a "
                f"string, got a list",
                source=source,
                name=name,
            )
        return json.dumps(value)[1:-1]

    def token(match: re.Match[str]) -> str:
        text_ = match.group(0)
        body = _string_body(text_)
        if body is None or "${" not in body:
            return text_
        whole = _WHOLE_RE.match(body)
        if whole is not None:
            return _as_json(values[whole.group(1)])
        return text_[0] + _EMBEDDED_RE.sub(embedded, body) + text_[-1]

    return _TOKEN_RE.sub(token, text)


# --- generated ACL parts (pure) --------------------------------------------------------------


def _check_site(site: str, *, source: str) -> None:
    problem = site_problem(site)
    if problem is not None:
        raise RouterConfigError(
            f"site name {site!r} {problem} (it becomes one key-expression chunk and part of a "
            "certificate name)",
            source=source,
            name="SITE",
        )


def _check_raw_keys(keys: Sequence[str], *, source: str, what: str) -> None:
    for key in keys:
        try:
            zenoh.KeyExpr(key)
        except zenoh.ZError as exc:
            raise RouterConfigError(
                f"{what}: invalid key expression {key!r}: {exc}", source=source, name=key
            ) from None
        if key == "**" or key.startswith(("fleetlink/", "@")):
            raise RouterConfigError(
                f"{what}: {key!r} is not a raw ROS topic key (expected e.g. '0/robot1/imu/**')",
                source=source,
                name=key,
            )


def _rule(rule_id: str, flow: str, messages: Sequence[str], keys: Sequence[str]) -> dict[str, Any]:
    return {
        "id": rule_id,
        "permission": "allow",
        "flows": [flow],
        "messages": list(messages),
        "key_exprs": list(keys),
    }


def cloud_site_acl(site: str, *, raw_keys: Sequence[str] = (), source: str = "<cloud>") -> AclBlock:
    """The cloud ACL entries for one site's edge (client certificate common name ``edge-<site>``).

    * ingress (edge -> cloud): anything on ``fleetlink/<site>/**``, plus puts on ``raw_keys``;
    * egress (cloud -> edge): data and replies on ``fleetlink/<site>/**``; declarations and
      queries on ``fleetlink/**`` (the uplink's wildcard queryables and fleet-wide admin
      queries), plus subscriber declarations on ``raw_keys``.
    """
    _check_site(site, source=source)
    _check_raw_keys(raw_keys, source=source, what=f"raw topics from site {site!r}")
    own = f"fleetlink/{site}/**"
    prefix = f"site-{site}"
    rules = [
        _rule(f"{prefix}-in", "ingress", ALL_MESSAGES, [own]),
        _rule(f"{prefix}-out", "egress", (*_DATA_OUT, "liveliness_token"), [own]),
        _rule(f"{prefix}-out-interest", "egress", _INTEREST, ["fleetlink/**"]),
    ]
    if raw_keys:
        rules += [
            _rule(f"{prefix}-raw-in", "ingress", ("put", "delete"), raw_keys),
            _rule(f"{prefix}-raw-out-interest", "egress", ("declare_subscriber",), raw_keys),
        ]
    subjects = [{"id": prefix, "cert_common_names": [edge_name(site)]}]
    policies = [{"id": prefix, "rules": [r["id"] for r in rules], "subjects": [s["id"] for s in subjects]}]
    return AclBlock(rules, subjects, policies)


def services_raw_acl(
    raw_keys: Sequence[str], *, services_subject: str = SERVICES_SUBJECT, source: str = "<cloud>"
) -> AclBlock:
    """Cloud rules letting the cloud services subscribe to the raw topics edges forward."""
    _check_raw_keys(raw_keys, source=source, what="raw_from")
    return AclBlock(
        rules=[
            _rule("services-raw-in", "ingress", ("declare_subscriber",), raw_keys),
            _rule("services-raw-out", "egress", ("put", "delete"), raw_keys),
        ],
        policies=[
            {
                "id": "services-raw",
                "rules": ["services-raw-in", "services-raw-out"],
                "subjects": [services_subject],
            }
        ],
    )


def edge_raw_acl(
    raw_keys: Sequence[str], *, wan_subject: str = WAN_SUBJECT, source: str = "<edge>"
) -> AclBlock:
    """Edge rules letting chosen raw topics out on the WAN (for the ACL subject ``wan_subject``)."""
    _check_raw_keys(raw_keys, source=source, what="raw_to_cloud")
    return AclBlock(
        rules=[
            _rule("wan-raw-out", "egress", ("put", "delete"), raw_keys),
            _rule("wan-raw-interest", "ingress", ("declare_subscriber",), raw_keys),
        ],
        policies=[{"id": "wan-raw", "rules": ["wan-raw-out", "wan-raw-interest"], "subjects": [wan_subject]}],
    )


def uncovered_raw_keys(raw_keys: Sequence[str], downsampling: Sequence[Mapping[str, Any]]) -> list[str]:
    """The raw keys that no egress ``put`` downsampling rule includes."""
    covering: list[zenoh.KeyExpr] = []
    for item in downsampling:
        flows = item.get("flows") or ["ingress", "egress"]
        if "egress" not in flows or "put" not in (item.get("messages") or []):
            continue
        covering += [zenoh.KeyExpr(rule["key_expr"]) for rule in item.get("rules") or []]
    return [key for key in raw_keys if not any(ke.includes(zenoh.KeyExpr(key)) for ke in covering)]


# --- zenoh.Config assembly -------------------------------------------------------------------


def _get(conf: zenoh.Config, key: str, *, source: str) -> Any:
    try:
        return json.loads(conf.get_json(key))
    except zenoh.ZError as exc:
        raise RouterConfigError(f"cannot read {key}: {exc}", source=source, name=key) from None


def _append_acl(conf: zenoh.Config, block: AclBlock, *, source: str) -> None:
    acl = _get(conf, "access_control", source=source)
    if not acl.get("enabled"):
        raise RouterConfigError(
            "access_control is not enabled, cannot add rules for sites or raw topics",
            source=source,
            name="access_control",
        )
    merged: dict[str, list[dict[str, Any]]] = {}
    for part in ("rules", "subjects", "policies"):
        merged[part] = [*(acl.get(part) or []), *getattr(block, part)]
        ids = [str(entry["id"]) for entry in merged[part] if entry.get("id") is not None]
        dupes = sorted({i for i in ids if ids.count(i) > 1})
        if dupes:
            raise RouterConfigError(
                f"access_control.{part}: duplicate id(s) {dupes}",
                source=source,
                name=f"access_control/{part}",
            )
    known = {part: {str(entry.get("id")) for entry in merged[part]} for part in ("rules", "subjects")}
    for policy in merged["policies"]:
        for part in ("rules", "subjects"):
            missing = sorted(set(policy.get(part) or []) - known[part])
            if missing:
                raise RouterConfigError(
                    f"access_control policy {policy.get('id')!r} names unknown {part} {missing}",
                    source=source,
                    name=missing[0],
                )
    for part, entries in merged.items():
        try:
            conf.insert_json5(f"access_control/{part}", json.dumps(entries))
        except zenoh.ZError as exc:
            raise RouterConfigError(
                f"access_control.{part}: {exc}", source=source, name=f"access_control/{part}"
            ) from None


def render_router_json5(
    text: str,
    *,
    source: str = "<text>",
    site: str | None = None,
    listen: Sequence[str] = (),
    connect: Sequence[str] = (),
    cert_dir: str | Path | None = None,
    sites: Sequence[str] = (),
    raw_to_cloud: Sequence[str] = (),
    raw_from: Mapping[str, Sequence[str]] | None = None,
    values: Mapping[str, Value] | None = None,
) -> zenoh.Config:
    """Render a template text into a ``zenoh.Config`` (no file access; see the module docstring)."""
    merged = _values(source, site=site, listen=listen, connect=connect, cert_dir=cert_dir, values=values)
    rendered = render_text(text, merged, source=source)
    try:
        conf = zenoh.Config.from_json5(rendered)
    except zenoh.ZError as exc:
        raise RouterConfigError(f"invalid zenoh config after rendering: {exc}", source=source) from None

    block = AclBlock()
    raw_from = raw_from or {}
    unknown = sorted(set(raw_from) - set(sites))
    if unknown:
        raise RouterConfigError(
            f"raw_from names site(s) {unknown} missing from sites", source=source, name=unknown[0]
        )
    for name in sites:
        block += cloud_site_acl(name, raw_keys=raw_from.get(name, ()), source=source)
    raw_keys = sorted({key for keys in raw_from.values() for key in keys})
    if raw_keys:
        block += services_raw_acl(raw_keys, source=source)
    if raw_to_cloud:
        missing = uncovered_raw_keys(raw_to_cloud, _get(conf, "downsampling", source=source))
        if missing:
            raise RouterConfigError(
                f"raw_to_cloud {missing}: raw topics may only cross the WAN downsampled, and no "
                "egress downsampling rule of this config covers them; add a rule to 'downsampling'",
                source=source,
                name=missing[0],
            )
        block += edge_raw_acl(raw_to_cloud, source=source)
    if block.rules or block.subjects or block.policies:
        _append_acl(conf, block, source=source)
    return conf


def _values(
    source: str,
    *,
    site: str | None,
    listen: Sequence[str],
    connect: Sequence[str],
    cert_dir: str | Path | None,
    values: Mapping[str, Value] | None,
) -> dict[str, Value]:
    merged: dict[str, Value] = {"LISTEN": list(listen), "CONNECT": list(connect)}
    if site is not None:
        _check_site(site, source=source)
        merged["SITE"] = site
    if cert_dir is not None:
        merged["CERT_DIR"] = str(cert_dir)
    merged.update(values or {})
    return merged


def concrete_json5(
    text: str,
    *,
    source: str = "<text>",
    header: str = "",
    site: str | None = None,
    listen: Sequence[str] = (),
    connect: Sequence[str] = (),
    cert_dir: str | Path | None = None,
    sites: Sequence[str] = (),
    raw_to_cloud: Sequence[str] = (),
    raw_from: Mapping[str, Sequence[str]] | None = None,
) -> str:
    """The text of a concrete config file that stock ``zenohd`` (or any Zenoh) reads.

    Without generated ACL parts it is the template with its placeholders filled in, comments
    kept; with them (``sites``, ``raw_to_cloud``, ``raw_from``) it is JSON holding the settings
    that differ from Zenoh's defaults. ``header`` (``//`` comment lines) goes on top.
    """
    conf = render_router_json5(
        text,
        source=source,
        site=site,
        listen=listen,
        connect=connect,
        cert_dir=cert_dir,
        sites=sites,
        raw_to_cloud=raw_to_cloud,
        raw_from=raw_from,
    )
    if sites or raw_to_cloud or raw_from:
        body = (
            json.dumps(_non_default(json.loads(str(conf)), json.loads(str(zenoh.Config()))), indent=2) + "\n"
        )
    else:
        merged = _values(source, site=site, listen=listen, connect=connect, cert_dir=cert_dir, values=None)
        body = render_text(text, merged, source=source)
    return header + body


def _non_default(value: Any, default: Any) -> Any:
    """The parts of a config (as JSON data) that differ from Zenoh's default config."""
    if not isinstance(value, dict) or not isinstance(default, dict):
        return value
    out = {}
    for key, item in value.items():
        if key not in default:
            out[key] = item
        elif item != default[key]:
            out[key] = _non_default(item, default[key])
    return out


def render_router_config(
    path: str | Path,
    *,
    site: str | None = None,
    listen: Sequence[str] = (),
    connect: Sequence[str] = (),
    cert_dir: str | Path | None = None,
    sites: Sequence[str] = (),
    raw_to_cloud: Sequence[str] = (),
    raw_from: Mapping[str, Sequence[str]] | None = None,
    values: Mapping[str, Value] | None = None,
) -> zenoh.Config:
    """Read a router template from ``path`` and render it (see :func:`render_router_json5`)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise RouterConfigError(f"cannot read router config: {exc.strerror}", source=str(path)) from None
    certificate = (
        Path(cert_dir) / f"{edge_name(site)}.pem" if site is not None and cert_dir is not None else None
    )
    if certificate is not None and site is not None and "edge-${SITE}.pem" in text and certificate.exists():
        # the site's router presents this certificate to the cloud: it must be the site's own
        # (a missing file is zenoh's error when the router opens)
        try:
            check_site_certificate(certificate, site)
        except CertError as exc:
            raise RouterConfigError(str(exc), source=str(path), name="CERT_DIR") from None
    return render_router_json5(
        text,
        source=str(path),
        site=site,
        listen=listen,
        connect=connect,
        cert_dir=cert_dir,
        sites=sites,
        raw_to_cloud=raw_to_cloud,
        raw_from=raw_from,
        values=values,
    )
