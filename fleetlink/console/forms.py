"""The mapping form <-> the admin API's request bodies and error lists (pure).

The form has one text input per mapping key (``name``, ``robot_type``, ``from``, ``to``, ``key``,
``type``, ``delivery``) and a ``stages`` text area holding the stage list in YAML, exactly as in
the config file (``- {type: throttle, hz: 2}``; JSON works too). Empty inputs are left out of
the body, so the edge's defaults and "required" messages apply.

The admin API answers 422 with problems that name a path in the body (``from``,
``stages[1].hz``, ``<root>``); ``field_errors`` puts each one on the form field that holds it
(``stages`` for ``stages[1].hz``), and whatever names no field on the form as a whole (``_form``).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict, Field

from fleetlink.console.errors import FormError

FIELDS = (
    "name",
    "robot_type",
    "from",
    "to",
    "key",
    "type",
    "delivery",
    "stages",
    "match",
    "mappings",
    "value",
    "robot",
    "mapping",
)
FORM = "_form"
_TEXT = ("robot_type", "from", "to", "key", "type", "delivery")
_HEAD = re.compile(r"[^.\[]+")


class MappingForm(BaseModel):
    """What the console's mapping form sends (every input as text)."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)

    name: str = Field(default="", max_length=200)
    robot_type: str = Field(default="", max_length=200)
    from_: str = Field(default="", alias="from", max_length=1000)
    to: str = Field(default="", max_length=1000)
    key: str = Field(default="", max_length=1000)
    type: str = Field(default="", max_length=300)
    delivery: str = Field(default="", max_length=40)
    stages: str = Field(default="", max_length=100_000)


def mapping_body(form: MappingForm, *, with_name: bool = True) -> dict[str, Any]:
    """The admin request body for ``form`` (``FormError`` when the stages text is not a YAML list)."""
    values = form.model_dump(by_alias=True)
    body: dict[str, Any] = {}
    name = values["name"].strip()
    if with_name and name:
        body["name"] = name
    for key in _TEXT:
        text = values[key].strip()
        if text:
            body[key] = text
    stages = parse_stages(values["stages"])
    if stages:
        body["stages"] = stages
    return body


def parse_stages(text: str) -> list[Any]:
    """The stage list from the form's YAML text ([] when blank)."""
    if not text.strip():
        return []
    data = _yaml(text, "stages")
    if data is None:
        return []
    if not isinstance(data, list):
        raise FormError({"stages": ["a list of stages is expected, e.g. - {type: throttle, hz: 2}"]})
    return data


def field_of(path: str) -> str:
    """The form field that holds ``path`` (``stages[1].hz`` -> ``stages``); ``_form`` if none."""
    match = _HEAD.match(path)
    head = match.group(0) if match else ""
    return head if head in FIELDS else FORM


def field_errors(problems: Iterable[Mapping[str, Any]]) -> dict[str, list[str]]:
    """Problems (``{path, message}``) -> form field -> messages. A message for a part of a field
    (``stages[1].hz``) keeps its path in front, so the operator knows which stage."""
    out: dict[str, list[str]] = {}
    for problem in problems:
        path = str(problem.get("path") or "<root>")
        message = str(problem.get("message") or "invalid")
        field = field_of(path)
        text = message if path == field else f"{path}: {message}"
        out.setdefault(field, []).append(text)
    return out


def refusal_fields(
    status: int, error: str | None, problems: Iterable[Mapping[str, Any]]
) -> dict[str, list[str]]:
    """Where a refused change shows its reasons: the problems' fields, else the form as a whole
    (a name taken, 409, shows on ``name``)."""
    fields = field_errors(problems)
    if not fields:
        where = "name" if status == 409 else FORM
        fields[where] = [error or f"refused ({status})"]
    return fields


class RobotTypeForm(BaseModel):
    """The robot-type editor: the namespace glob, and optionally the type's whole mapping list
    in YAML (as under ``robot_types.<name>.mappings`` in the config file)."""

    model_config = ConfigDict(extra="forbid")

    match: str = Field(default="", max_length=500)
    mappings: str = Field(default="", max_length=200_000)


def robot_type_body(form: RobotTypeForm) -> dict[str, Any]:
    """The admin request body (``FormError`` on ``mappings`` when its YAML is not a list)."""
    body: dict[str, Any] = {}
    if form.match.strip():
        body["match"] = form.match.strip()
    if form.mappings.strip():
        mappings = _yaml(form.mappings, "mappings")
        if not isinstance(mappings, list):
            raise FormError(
                {"mappings": ["a list of mappings is expected, e.g. - {name: ir, from: ..., to: ...}"]}
            )
        body["mappings"] = mappings
    return body


class CommandForm(BaseModel):
    """Send one command: the command mapping, the robot (the record's key) and the value in
    YAML (the fields of the mapping's ROS type; fields left out take their defaults)."""

    model_config = ConfigDict(extra="forbid")

    mapping: str = Field(min_length=1, max_length=200)
    robot: str = Field(min_length=1, max_length=200)
    value: str = Field(default="", max_length=100_000)


def parse_value(text: str) -> dict[str, Any]:
    """A command's value from YAML (``{}`` when blank); ``FormError`` on ``value`` otherwise."""
    if not text.strip():
        return {}
    data = _yaml(text, "value")
    if not isinstance(data, dict):
        raise FormError({"value": ["a mapping of the message's fields is expected, e.g. {data: 1}"]})
    return data


def _yaml(text: str, field: str) -> Any:
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise FormError({field: [f"not valid YAML{where}: {problem}"]}) from None
