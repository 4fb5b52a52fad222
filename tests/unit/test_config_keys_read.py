"""Every key docs/reference/config.md documents is read by the code somewhere.

A key is read when its field's name is an attribute read (``x.field`` or ``getattr(x, "field")``)
in fleetlink's source outside the validators of the config models: a field that is declared,
validated and documented but never used fails here (as ``ingest.batch_deadline_s`` once did).
"""

from __future__ import annotations

import ast
import os
import re
import typing
from collections.abc import Iterator
from pathlib import Path

import pytest
from pydantic import BaseModel

from fleetlink.cli.configs import KINDS, model_for
from fleetlink.cli.docgen import render
from tests.paths import DOCS, ROOT

pytestmark = pytest.mark.unit

REFERENCE = DOCS / "reference" / "config.md"
_VALIDATORS = {"field_validator", "model_validator"}


def documented_keys() -> dict[str, set[str]]:
    """Kind -> the key paths of its table in the reference."""
    keys: dict[str, set[str]] = {}
    kind = ""
    for line in REFERENCE.read_text().splitlines():
        heading = re.match(r"## (\w+) ", line)
        if heading:
            kind = heading.group(1)
            keys[kind] = set()
        row = re.match(r"\| `([^`]+)` \|", line)
        if row and kind:
            keys[kind].add(row.group(1))
    return keys


def _single_model(annotation: typing.Any) -> type[BaseModel] | None:
    found = [a for a in (annotation, *typing.get_args(annotation)) if isinstance(a, type)]
    found += [m for a in typing.get_args(annotation) if (m := _single_model(a)) is not None]
    models = {m for m in found if issubclass(m, BaseModel)}
    return models.pop() if len(models) == 1 else None


def fields(model: type[BaseModel], prefix: str = "") -> Iterator[tuple[str, str]]:
    """(key path as the reference writes it, field name) of a model and its sections."""
    for name, field in model.model_fields.items():
        path = f"{prefix}{field.alias or name}"
        yield path, name
        nested = _single_model(field.annotation)
        if nested is None:
            continue
        origin = typing.get_origin(field.annotation)
        marker = "[]." if origin is list else ".<name>." if origin is dict else "."
        yield from fields(nested, f"{path}{marker}")


def _in_validator(node: ast.AST, parents: dict[ast.AST, ast.AST]) -> bool:
    while node in parents:
        node = parents[node]
        if isinstance(node, ast.FunctionDef):
            for decorator in node.decorator_list:
                target = decorator.func if isinstance(decorator, ast.Call) else decorator
                if isinstance(target, ast.Name) and target.id in _VALIDATORS:
                    return True
    return False


def attributes_read(source: str) -> set[str]:
    """Attribute names read in ``source`` outside pydantic validators."""
    tree = ast.parse(source)
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Load):
            name = node.attr
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id == "getattr"
            and len(node.args) >= 2
            and isinstance(node.args[1], ast.Constant)
            and isinstance(node.args[1].value, str)
        ):
            name = node.args[1].value
        else:
            continue
        if not _in_validator(node, parents):
            found.add(name)
    return found


def package_reads() -> set[str]:
    found: set[str] = set()
    for folder, _dirs, files in os.walk(ROOT / "fleetlink", followlinks=True):
        for name in files:
            if name.endswith(".py"):
                found |= attributes_read((Path(folder) / name).read_text())
    return found


def test_the_reference_lists_every_config_key() -> None:
    assert REFERENCE.read_text() == render()
    keys = documented_keys()
    assert set(keys) == set(KINDS)
    for kind, documented in keys.items():
        assert documented == {path for path, _name in fields(model_for(kind))}, kind


def test_every_documented_key_is_read_by_the_code() -> None:
    reads = package_reads()
    unread = [
        f"{kind}: {path}"
        for kind in documented_keys()
        for path, name in fields(model_for(kind))
        if name not in reads
    ]
    assert unread == [], "declared and documented, but nothing reads them"


def test_a_field_only_its_validator_reads_counts_as_unread() -> None:
    source = """
class WanSection(Section):
    deadline_s: float = 60.0

    @model_validator(mode="after")
    def _check(self) -> WanSection:
        assert self.deadline_s > 0
        return self

def use(config):
    return config.wan.linger, getattr(config, "codec")
"""
    reads = attributes_read(source)
    assert {"wan", "linger", "codec"} <= reads
    assert "deadline_s" not in reads
