"""The admin operations as Zenoh keys (pure: key expressions in, operations and replies out).

Keys of one site (``fleetlink/<site>/admin/...``)::

    robots  topics  mappings  robot_types  health  overlay     GET (a query without payload)
    mappings              + JSON payload: add          (or op=add)
    mappings/<name>       GET; + payload: change (op=put); op=delete
    robot_types/<name>    GET; + payload: create or change (op=put); op=delete
    dry-run               + payload: dry run           (or op=dry-run)

A GET may use wildcards (``fleetlink/*/admin/health``, ``fleetlink/site-a/admin/mappings/*``):
every concrete key of this site the query intersects is answered, each on its own concrete key
(a reply on a wildcard key is dropped on the way back across routers). A change must name one
concrete key. Each reply is a JSON envelope: ``{"status": 200, "site", "edge_id", "body"}`` or
``{"status": 4xx, "site", "edge_id", "error", "problems"}``, with the HTTP API's status codes.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import zenoh
from pydantic import BaseModel

from fleetlink.edge.admin.errors import AdminError, InvalidChangeError
from fleetlink.edge.admin.service import AdminService

COLLECTIONS = ("robots", "topics", "mappings", "robot_types", "health", "overlay")
ITEMS = ("mappings", "robot_types")
OPS = ("get", "add", "put", "delete", "dry-run")


@dataclass(frozen=True, slots=True)
class Target:
    """One answer to give: on ``key``, ``op`` on ``resource`` (and ``name``); or an error."""

    key: str
    resource: str
    name: str | None = None
    op: str = "get"
    status: int | None = None
    error: str | None = None


def _prefix(site: str) -> str:
    return f"fleetlink/{site}/admin"


def _intersects(a: str, b: str) -> bool:
    try:
        return bool(zenoh.KeyExpr(a).intersects(zenoh.KeyExpr(b)))
    except zenoh.ZError:
        return False


def _concrete(key: str) -> bool:
    return "*" not in key and "$" not in key


def targets(
    site: str, key: str, op: str | None, has_payload: bool, names: Callable[[str], Iterable[str]]
) -> list[Target]:
    """What a query on ``key`` asks of this site. ``names(resource)`` lists existing mappings or
    robot types (for wildcard GETs over items)."""
    prefix = _prefix(site)
    if op is not None and op not in OPS:
        where = key if _concrete(key) else prefix + "/mappings"
        return [Target(where, "", status=400, error=f"unknown op {op!r} (one of: {', '.join(OPS)})")]
    if _concrete(key):
        return [_one(prefix, key, op, has_payload)]
    out = [Target(f"{prefix}/{c}", c) for c in COLLECTIONS if _intersects(key, f"{prefix}/{c}")]
    for resource in ITEMS:
        for name in names(resource):
            item = f"{prefix}/{resource}/{name}"
            if _intersects(key, item):
                out.append(Target(item, resource, name))
    if out and ((op or "get") != "get" or has_payload):
        error = "a change must name one concrete key (no wildcards)"
        return [Target(out[0].key, "", status=400, error=error)]
    return out


def _one(prefix: str, key: str, op: str | None, has_payload: bool) -> Target:
    rest = key[len(prefix) + 1 :] if key.startswith(prefix + "/") else ""
    parts = rest.split("/") if rest else []
    if len(parts) == 1 and parts[0] in (*COLLECTIONS, "dry-run"):
        resource, name = parts[0], None
    elif len(parts) == 2 and parts[0] in ITEMS:
        resource, name = parts
    else:
        return Target(key, "", status=404, error=f"no admin resource at {key!r}")
    default = "get"
    if has_payload:
        default = "dry-run" if resource == "dry-run" else ("add" if name is None else "put")
    chosen = op or default
    allowed = {
        ("dry-run", None): {"dry-run"},
        ("mappings", None): {"get", "add"},
        ("mappings", "item"): {"get", "put", "delete"},
        ("robot_types", "item"): {"get", "put", "delete"},
    }.get((resource, None if name is None else "item"), {"get"})
    if chosen not in allowed:
        return Target(
            key,
            resource,
            name,
            status=405,
            error=f"op {chosen!r} is not possible on {resource}{'/<name>' if name else ''} "
            f"(possible: {', '.join(sorted(allowed))})",
        )
    if chosen in ("add", "put", "dry-run") and not has_payload:
        return Target(key, resource, name, status=400, error=f"op {chosen!r} needs a JSON payload")
    return Target(key, resource, name, chosen)


def _json(value: Any) -> Any:
    if isinstance(value, BaseModel):
        return value.model_dump(mode="json", by_alias=True)
    if isinstance(value, list):
        return [_json(v) for v in value]
    return value


def execute(service: AdminService, target: Target, body: Any) -> tuple[int, Any]:
    """Run one target against the service: (status, JSON-ready body or error envelope part)."""
    if target.status is not None:
        return target.status, {"error": target.error, "problems": []}
    try:
        return _run(service, target, body)
    except InvalidChangeError as exc:
        return exc.status, {"error": exc.summary, "problems": [p.as_dict() for p in exc.problems]}
    except AdminError as exc:
        return exc.status, {"error": str(exc), "problems": []}


def _run(service: AdminService, target: Target, body: Any) -> tuple[int, Any]:  # noqa: PLR0911 - a dispatch table
    resource, name, op = target.resource, target.name, target.op
    if op == "get" and name is None:
        if resource == "health":
            health = service.health()
            return health.http_status, {"body": health.as_dict()}
        reads: dict[str, Callable[[], Any]] = {
            "robots": service.robots,
            "topics": service.topics,
            "mappings": service.mappings,
            "robot_types": service.robot_types,
            "overlay": lambda: service.overlay,
        }
        return 200, {"body": _json(reads[resource]())}
    if op == "get" and name is not None:
        if resource == "mappings":
            return 200, {"body": _json(service.mapping(name))}
        found = [t for t in service.robot_types() if t.name == name]
        if not found:
            return 404, {"error": f"no robot type named {name!r}", "problems": []}
        return 200, {"body": _json(found[0])}
    if op == "dry-run":
        return 200, {"body": _json(service.dry_run(body))}
    if op == "add":
        change = service.add_mapping(body)
    elif op == "put" and resource == "mappings" and name is not None:
        change = service.change_mapping(name, {"name": name, **body} if isinstance(body, dict) else body)
    elif op == "put" and name is not None:
        change = service.put_robot_type(name, body)
    elif resource == "mappings" and name is not None:
        change = service.remove_mapping(name)
    elif name is not None:
        change = service.remove_robot_type(name)
    else:  # pragma: no cover - targets() only lets the combinations above through
        return 400, {"error": "unsupported operation", "problems": []}
    return (201 if change.status == "created" else 200), {"body": _json(change)}


def envelope(status: int, part: Any, *, site: str, edge_id: str) -> bytes:
    """A reply's JSON bytes: ``status``, ``site``, ``edge_id`` and the keys of ``part``."""
    return json.dumps({"status": status, "site": site, "edge_id": edge_id, **part}).encode()


def parse_body(payload: bytes | None) -> tuple[Any, str | None]:
    """The query's JSON payload (``None`` without one), or an error message."""
    if payload is None or payload == b"":
        return None, None
    try:
        return json.loads(payload), None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        return None, f"the payload is not JSON: {exc}"
