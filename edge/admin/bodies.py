"""Request bodies of the admin API, as documented in the OpenAPI document.

They are the config file's own models (a mapping exactly as in the YAML) plus ``robot_type``;
HTTP requests are checked against them first, then the whole change is validated by
``edge.admin.changes`` (which the Zenoh admin space uses directly with the raw JSON).
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from fleetlink.common.names import KeyChunk, NamespaceGlob
from fleetlink.edge.config import MappingConfig, RobotMappingConfig


class MappingBody(MappingConfig):
    """A mapping as in the config file; ``robot_type`` names the robot type whose template it is
    (absent or null: a site-level mapping)."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True, title="MappingBody")

    robot_type: KeyChunk | None = None


class MappingChangeBody(MappingBody):
    """A mapping's new definition; ``name`` may be left out (it is the one in the URL)."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True, title="MappingChangeBody")

    name: KeyChunk | None = None  # type: ignore[assignment]


class DryRunBody(MappingBody):
    """A mapping to try; ``name`` may be left out."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True, title="DryRunBody")

    name: KeyChunk = "dry-run"


class RobotTypeBody(BaseModel):
    """A robot type: its namespace glob, and optionally its complete list of mappings (the type's
    other mappings are then removed; leave it out to change ``match`` only)."""

    model_config = ConfigDict(extra="forbid", title="RobotTypeBody")

    match: NamespaceGlob = Field(examples=["/tb4_*"])
    mappings: list[RobotMappingConfig] | None = None


def raw(body: BaseModel) -> dict[str, Any]:
    """What the client sent, as YAML-shaped data (aliases, only the keys given)."""
    return body.model_dump(mode="json", by_alias=True, exclude_unset=True)
