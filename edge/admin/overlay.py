"""The runtime overlay: what the admin API changed on top of the config file (pure).

The overlay is state, not a log: mappings and robot types added or changed (full definitions,
by name) and the names removed. ``apply_overlay`` lays it over the config file's data in a
fixed order, so the result does not depend on the order the changes were made in:

1. remove ``removed_robot_types`` (with their mappings);
2. add or change ``robot_types`` (``match`` only; a type created here starts with no mappings);
3. remove ``removed_mappings``;
4. add or change ``mappings``: one that exists keeps its place when it stays with the same
   owner (site or robot type); otherwise it is appended to its owner's list.

Persisted as YAML next to the spool (``edge.admin.store``) and applied at start.
"""

from __future__ import annotations

import copy
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from fleetlink.common.configfile import PathPart


class RobotTypeOverlay(BaseModel):
    """A robot type created or changed at runtime: its namespace glob only."""

    model_config = ConfigDict(extra="forbid")

    match: str


class Overlay(BaseModel):
    """What the admin API changed. ``mappings`` holds request-shaped dicts: a mapping as in the
    YAML plus ``robot_type`` (absent or null: a site-level mapping)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    version: Literal[1] = 1
    robot_types: dict[str, RobotTypeOverlay] = {}
    removed_robot_types: list[str] = []
    mappings: list[dict[str, Any]] = Field(default_factory=list)
    removed_mappings: list[str] = []

    @field_validator("mappings")
    @classmethod
    def _named(cls, value: list[dict[str, Any]]) -> list[dict[str, Any]]:
        seen: set[str] = set()
        for index, mapping in enumerate(value):
            name = mapping.get("name")
            if not isinstance(name, str):
                raise ValueError(f"entry {index} has no mapping name")
            if name in seen:
                raise ValueError(f"mapping {name!r} is listed twice")
            seen.add(name)
        return value

    @property
    def empty(self) -> bool:
        """Whether the overlay changes nothing."""
        return not (self.robot_types or self.removed_robot_types or self.mappings or self.removed_mappings)

    def mapping(self, name: str) -> dict[str, Any] | None:
        """The overlay's entry for the mapping ``name``; ``None`` when it has none."""
        return next((m for m in self.mappings if m.get("name") == name), None)

    def with_mapping(self, body: dict[str, Any]) -> Overlay:
        """Add or replace the overlay entry of ``body['name']``."""
        name = body["name"]
        kept = [m for m in self.mappings if m.get("name") != name]
        return self.model_copy(update={"mappings": [*kept, body]})

    def without_mapping(self, name: str, *, removed: bool) -> Overlay:
        """Drop the overlay entry of ``name``; with ``removed`` (the config file declares it too) list it
        among the removed mappings."""
        kept = [m for m in self.mappings if m.get("name") != name]
        gone = sorted({*self.removed_mappings, name}) if removed else self.removed_mappings
        return self.model_copy(update={"mappings": kept, "removed_mappings": gone})

    def with_robot_type(self, name: str, match: str) -> Overlay:
        """Add or replace the robot type ``name`` with ``match``."""
        types = {**self.robot_types, name: RobotTypeOverlay(match=match)}
        return self.model_copy(update={"robot_types": types})

    def without_robot_type(self, name: str, *, removed: bool) -> Overlay:
        """Drop the robot type ``name`` and its mappings from the overlay; with ``removed`` (the config
        file declares it too) list it among the removed robot types."""
        types = {k: v for k, v in self.robot_types.items() if k != name}
        kept = [m for m in self.mappings if m.get("robot_type") != name]
        gone = sorted({*self.removed_robot_types, name}) if removed else self.removed_robot_types
        return self.model_copy(update={"robot_types": types, "mappings": kept, "removed_robot_types": gone})


REVEAL_SECRETS = {"reveal_secrets": True}
"""The dump context in which secret fields dump their value, not ``**********``."""


def config_data(config: BaseModel) -> dict[str, Any]:
    """A validated config as plain data that validates to the same config again (secrets such
    as ``objects.secret_access_key`` included: ``REVEAL_SECRETS``)."""
    return config.model_dump(mode="json", by_alias=True, context=REVEAL_SECRETS)


def mapping_body(mapping: dict[str, Any]) -> dict[str, Any]:
    """An overlay/request entry without ``robot_type``: the shape the YAML has."""
    return {k: v for k, v in mapping.items() if k != "robot_type"}


def locate_mapping(data: dict[str, Any], name: str) -> tuple[PathPart, ...] | None:
    """Where the mapping ``name`` sits in config data: ``("mappings", 2)`` or
    ``("robot_types", "tb4", "mappings", 0)``; ``None`` when absent."""
    for index, mapping in enumerate(_list(data, "mappings")):
        if isinstance(mapping, dict) and mapping.get("name") == name:
            return ("mappings", index)
    for type_name, robot_type in _types(data).items():
        for index, mapping in enumerate(_list(robot_type, "mappings")):
            if isinstance(mapping, dict) and mapping.get("name") == name:
                return ("robot_types", type_name, "mappings", index)
    return None


def owner_of(data: dict[str, Any], name: str) -> str | None:
    """The robot type a mapping belongs to (``None``: site-level or absent)."""
    where = locate_mapping(data, name)
    return str(where[1]) if where is not None and where[0] == "robot_types" else None


def apply_overlay(base: dict[str, Any], overlay: Overlay) -> dict[str, Any]:
    """The config data with ``overlay`` applied (``base`` is not modified)."""
    data = copy.deepcopy(base)
    data.setdefault("robot_types", {})
    data.setdefault("mappings", [])
    types = _types(data)
    for name in overlay.removed_robot_types:
        types.pop(name, None)
    for name, robot_type in overlay.robot_types.items():
        if name in types and isinstance(types[name], dict):
            types[name]["match"] = robot_type.match
        else:
            types[name] = {"match": robot_type.match, "mappings": []}
    for name in overlay.removed_mappings:
        _remove(data, name)
    for entry in overlay.mappings:
        _upsert(data, entry)
    return data


def _types(data: dict[str, Any]) -> dict[str, Any]:
    types = data.get("robot_types")
    return types if isinstance(types, dict) else {}


def _list(node: Any, key: str) -> list[Any]:
    value = node.get(key) if isinstance(node, dict) else None
    return value if isinstance(value, list) else []


def _remove(data: dict[str, Any], name: str) -> None:
    where = locate_mapping(data, name)
    if where is None:
        return
    if where[0] == "mappings":
        del data["mappings"][where[1]]
    else:
        del data["robot_types"][where[1]]["mappings"][where[3]]


def _upsert(data: dict[str, Any], entry: dict[str, Any]) -> None:
    name = entry.get("name")
    owner = entry.get("robot_type")
    body = mapping_body(entry)
    where = locate_mapping(data, str(name))
    same_owner = where is not None and (
        (owner is None and where[0] == "mappings") or (where[0] == "robot_types" and where[1] == owner)
    )
    if where is not None and same_owner:
        target = data["mappings"] if owner is None else data["robot_types"][owner]["mappings"]
        target[int(where[-1])] = body
        return
    if where is not None:
        _remove(data, str(name))
    if owner is None:
        data["mappings"].append(body)
        return
    robot_type = _types(data).get(owner)
    if isinstance(robot_type, dict):
        robot_type.setdefault("mappings", [])
        if isinstance(robot_type["mappings"], list):
            robot_type["mappings"].append(body)
