"""Admin changes as pure functions: (config file, overlay, request) -> new overlay + new config.

Every change is validated as a whole before anything is applied: the request body is checked
for shape, the overlay is updated, laid over the config file's data, and the result validated
with the edge's own config model (``EdgeConfig``), so a change is accepted exactly when the
same edit in the YAML file would pass ``fleetlink validate``. Stage lists are also built once
(``edge.stages.build_pipeline``) to catch what only the pipeline checks (duplicate stage names).
Problems come back as ``InvalidChangeError`` with body-relative paths.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from pydantic import ValidationError

from fleetlink.common.configfile import PathPart, format_path
from fleetlink.edge.admin.errors import (
    ConflictError,
    FieldProblem,
    InvalidChangeError,
    NotFoundError,
    OverlayError,
)
from fleetlink.edge.admin.overlay import Overlay, apply_overlay, locate_mapping, owner_of
from fleetlink.edge.admin.problems import problems_from
from fleetlink.edge.config import EdgeConfig, MappingConfig
from fleetlink.edge.stages import StageConfigError, build_pipeline


@dataclass(frozen=True, slots=True)
class Proposal:
    """A validated change, ready to persist and install."""

    overlay: Overlay
    config: EdgeConfig
    created: bool = False


def effective(base: dict[str, Any], overlay: Overlay, *, source: str = "overlay") -> EdgeConfig:
    """The config the edge runs: the config file's data with the overlay applied (at start).
    Raises ``OverlayError`` listing every problem when the overlay no longer fits."""
    data = apply_overlay(base, overlay)
    lost = [m["name"] for m in overlay.mappings if locate_mapping(data, str(m["name"])) is None]
    problems = [f"mapping {name!r}: its robot type no longer exists" for name in lost]
    try:
        config = EdgeConfig.model_validate(data)
    except ValidationError as exc:
        problems += [f"{p.path}: {p.message}" for p in problems_from(exc, data)]
        config = None
    if problems or config is None:
        listing = "\n  ".join(problems)
        raise OverlayError(
            f"{source}: the admin changes saved here no longer fit the config file "
            f"(fix or delete the file to start from the config file alone):\n  {listing}"
        )
    return config


def add_mapping(base: dict[str, Any], overlay: Overlay, body: Any) -> Proposal:
    """Add the mapping in ``body``; raises ``ConflictError`` when one of that name exists and
    ``InvalidChangeError`` when the result would not validate."""
    entry = _mapping_entry(body, name=None)
    current = apply_overlay(base, overlay)
    name = entry["name"]
    if locate_mapping(current, name) is not None:
        raise ConflictError(f"a mapping named {name!r} exists already (change it with PUT /mappings/{name})")
    _check_owner(current, entry)
    return Proposal(*_validated(base, overlay.with_mapping(entry), name), created=True)


def change_mapping(base: dict[str, Any], overlay: Overlay, name: str, body: Any) -> Proposal:
    """Replace the mapping ``name`` with ``body``; raises ``NotFoundError`` when there is none and
    ``InvalidChangeError`` when the result would not validate."""
    current = apply_overlay(base, overlay)
    if locate_mapping(current, name) is None:
        raise NotFoundError(f"no mapping named {name!r}")
    entry = _mapping_entry(body, name=name)
    _check_owner(current, entry)
    return Proposal(*_validated(base, overlay.with_mapping(entry), name))


def remove_mapping(base: dict[str, Any], overlay: Overlay, name: str) -> Proposal:
    """Remove the mapping ``name`` (from the overlay, and from the config file's declarations when it is
    declared there); raises ``NotFoundError`` when there is none."""
    current = apply_overlay(base, overlay)
    if locate_mapping(current, name) is None:
        raise NotFoundError(f"no mapping named {name!r}")
    in_base = locate_mapping(apply_overlay(base, _without_mapping_entries(overlay)), name) is not None
    new = overlay.without_mapping(name, removed=in_base)
    return Proposal(*_validated(base, new, None))


def put_robot_type(base: dict[str, Any], overlay: Overlay, name: str, body: Any) -> Proposal:
    """Create or change a robot type: ``match``, and when ``mappings`` is given, exactly those
    mappings (the type's other mappings are removed)."""
    if not isinstance(body, dict):
        raise _shape("<root>", "expected an object with 'match' (and optionally 'mappings')")
    unknown = sorted(set(body) - {"match", "mappings"})
    if unknown:
        raise _shape(unknown[0], "unknown key (not allowed here; check the spelling)")
    match = body.get("match")
    if not isinstance(match, str):
        raise _shape("match", "a namespace glob such as '/tb4_*' is required")
    current = apply_overlay(base, overlay)
    created = name not in current.get("robot_types", {})
    new = overlay.with_robot_type(name, match)
    mappings = body.get("mappings")
    if mappings is not None:
        if not isinstance(mappings, list):
            raise _shape("mappings", "expected a list of mappings")
        entries = [_mapping_entry(m, name=None, where=("mappings", i)) for i, m in enumerate(mappings)]
        _check_type_mappings(current, name, entries)
        wanted = {e["name"] for e in entries}
        for old in _type_mapping_names(current, name) - wanted:
            new = _drop_mapping(base, new, old)
        for entry in entries:
            new = new.with_mapping({**entry, "robot_type": name})
    proposal = _validated(base, new, None, type_name=name)
    return Proposal(*proposal, created=created)


def remove_robot_type(base: dict[str, Any], overlay: Overlay, name: str) -> Proposal:
    """Remove the robot type ``name`` with its mappings; raises ``NotFoundError`` when there is none."""
    current = apply_overlay(base, overlay)
    if name not in current.get("robot_types", {}):
        raise NotFoundError(f"no robot type named {name!r}")
    in_base = name in apply_overlay(base, Overlay(removed_robot_types=overlay.removed_robot_types)).get(
        "robot_types", {}
    )
    return Proposal(*_validated(base, overlay.without_robot_type(name, removed=in_base), None))


def candidate_mapping(base: dict[str, Any], overlay: Overlay, body: Any) -> tuple[EdgeConfig, str]:
    """For a dry run: the config as it would be with ``body`` added (or replacing the mapping of
    the same name), validated; returns it and the mapping's name. Nothing is kept."""
    entry = _mapping_entry(body, name=None)
    current = apply_overlay(base, overlay)
    _check_owner(current, entry)
    _, config = _validated(base, overlay.with_mapping(entry), entry["name"])
    return config, entry["name"]


# -- helpers -----------------------------------------------------------------------------------------
def _shape(path: str, message: str) -> InvalidChangeError:
    return InvalidChangeError("invalid request", (FieldProblem(path=path, message=message),))


def _mapping_entry(body: Any, *, name: str | None, where: tuple[PathPart, ...] = ()) -> dict[str, Any]:
    """Check what must hold before the overlay can take the body: an object with a text name."""
    at = format_path(where)
    if not isinstance(body, dict):
        raise _shape(at, "expected an object: a mapping as in the config file, plus optional 'robot_type'")
    given = body.get("name", name)
    if not isinstance(given, str) or not given:
        raise _shape(format_path((*where, "name")), "a mapping name (text) is required")
    if name is not None and given != name:
        raise _shape(
            format_path((*where, "name")),
            f"the body names {given!r} but the URL names {name!r}; a mapping cannot be renamed "
            "(add the new one and remove the old one)",
        )
    robot_type = body.get("robot_type")
    if robot_type is not None and not isinstance(robot_type, str):
        raise _shape(format_path((*where, "robot_type")), "a robot type name (text) or null")
    return {**body, "name": given}


def _check_owner(current: dict[str, Any], entry: dict[str, Any]) -> None:
    robot_type = entry.get("robot_type")
    types = current.get("robot_types", {})
    if robot_type is not None and robot_type not in types:
        known = ", ".join(sorted(types)) or "none"
        raise _shape("robot_type", f"unknown robot type {robot_type!r} (known: {known})")


def _type_mapping_names(data: dict[str, Any], name: str) -> set[str]:
    robot_type = data.get("robot_types", {}).get(name)
    if not isinstance(robot_type, dict):
        return set()
    return {str(m.get("name")) for m in robot_type.get("mappings", []) if isinstance(m, dict)}


def _check_type_mappings(current: dict[str, Any], name: str, entries: Iterable[dict[str, Any]]) -> None:
    problems = []
    seen: set[str] = set()
    for index, entry in enumerate(entries):
        if "robot_type" in entry and entry["robot_type"] not in (None, name):
            problems.append(
                FieldProblem(
                    f"mappings[{index}].robot_type", f"must be {name!r} (or left out) in this robot type"
                )
            )
        mapping = entry["name"]
        owner = owner_of(current, mapping)
        elsewhere = locate_mapping(current, mapping) is not None and owner != name
        if mapping in seen or elsewhere:
            place = format_path(locate_mapping(current, mapping) or ())
            where = "twice in this request" if mapping in seen else f"already by {place}"
            problems.append(
                FieldProblem(
                    f"mappings[{index}].name",
                    f"the name {mapping!r} is used {where}; mapping names are unique per edge",
                )
            )
        seen.add(mapping)
    if problems:
        raise InvalidChangeError("invalid robot type", tuple(problems))


def _without_mapping_entries(overlay: Overlay) -> Overlay:
    return overlay.model_copy(update={"mappings": []})


def _drop_mapping(base: dict[str, Any], overlay: Overlay, name: str) -> Overlay:
    in_base = locate_mapping(apply_overlay(base, _without_mapping_entries(overlay)), name) is not None
    return overlay.without_mapping(name, removed=in_base)


def _validated(
    base: dict[str, Any], overlay: Overlay, mapping: str | None, *, type_name: str | None = None
) -> tuple[Overlay, EdgeConfig]:
    data = apply_overlay(base, overlay)
    prefix: tuple[PathPart, ...] | None = None
    if mapping is not None:
        prefix = locate_mapping(data, mapping)
    elif type_name is not None:
        prefix = ("robot_types", type_name)
    try:
        config = EdgeConfig.model_validate(data)
    except ValidationError as exc:
        problems = problems_from(exc, data, body_prefix=prefix)
        raise InvalidChangeError("the change does not validate", problems) from None
    _check_stages(config, prefix)
    return overlay, config


def _check_stages(config: EdgeConfig, prefix: tuple[PathPart, ...] | None) -> None:
    problems = []
    declared: list[tuple[tuple[PathPart, ...], MappingConfig]] = [
        (("mappings", i), m) for i, m in enumerate(config.mappings)
    ]
    declared += [
        (("robot_types", t, "mappings", i), m)
        for t, rt in config.robot_types.items()
        for i, m in enumerate(rt.mappings)
    ]
    for where, mapping in declared:
        if prefix is not None and where[: len(prefix)] != prefix:
            continue
        try:
            build_pipeline(list(mapping.stages), name=mapping.name)
        except StageConfigError as exc:
            full = (*where, "stages")
            rel = full[len(prefix) :] if prefix is not None else full
            problems.append(FieldProblem(format_path(rel), str(exc), format_path(full)))
    if problems:
        raise InvalidChangeError("the change does not validate", tuple(problems))
