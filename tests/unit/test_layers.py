"""Layers only point down (docs/architecture.md).

Every import between fleetlink's parts, read from the source (also the ones inside functions and
``TYPE_CHECKING`` blocks), goes to a lower layer or stays inside its own part; parts of one layer
never import each other.
"""

from __future__ import annotations

import ast
import os
from pathlib import Path

import pytest

from tests.paths import ROOT

pytestmark = pytest.mark.unit

PACKAGE = ROOT / "fleetlink"

LAYERS: tuple[tuple[str, ...], ...] = (
    ("fleetlink", "fleetlink.common"),
    ("fleetlink.wire", "fleetlink.schemas"),
    ("fleetlink.roswire",),
    ("fleetlink.edge", "fleetlink.uplink", "fleetlink.repeater"),
    ("fleetlink.console",),
    ("fleetlink.localstack", "fleetlink.examples"),
    ("fleetlink.demo",),
    ("fleetlink.cli",),
)
"""From the ground floor up. ``fleetlink`` alone is the root package (its version)."""


def part_of(module: str) -> str:
    """The part (a name of ``LAYERS``) a module belongs to (``python -m fleetlink`` is the CLI's)."""
    if module == "fleetlink.__main__":
        return "fleetlink.cli"
    parts = module.split(".")
    candidate = ".".join(parts[:2])
    known = {name for layer in LAYERS for name in layer}
    return candidate if candidate in known else "fleetlink"


def rank(part: str) -> int:
    return next(i for i, layer in enumerate(LAYERS) if part in layer)


def modules() -> dict[str, Path]:
    out: dict[str, Path] = {}
    for folder, _dirs, files in os.walk(PACKAGE, followlinks=True):
        for name in files:
            if not name.endswith(".py"):
                continue
            path = Path(folder) / name
            rel = path.relative_to(PACKAGE.parent).with_suffix("")
            dotted = ".".join(rel.parts)
            out[dotted.removesuffix(".__init__")] = path
    return out


def imports_of(module: str, path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(), str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join([*base, node.module] if node.module else base)
            else:
                target = node.module or ""
            found.append((node.lineno, target))
    return [(line, name) for line, name in found if name == "fleetlink" or name.startswith("fleetlink.")]


def violations() -> list[str]:
    out = []
    for module, path in sorted(modules().items()):
        mine = part_of(module)
        for line, target in imports_of(module, path):
            theirs = part_of(target)
            if theirs == mine or rank(theirs) < rank(mine) or target == "fleetlink":
                continue
            where = path.relative_to(ROOT)
            out.append(f"{where}:{line}: {mine} (layer {rank(mine)}) imports {target} (layer {rank(theirs)})")
    return out


def test_every_module_is_in_a_layer() -> None:
    assert len(modules()) > 200
    assert all(part_of(m) for m in modules())


def test_imports_only_point_down() -> None:
    assert violations() == []


def test_the_checker_sees_an_upward_import(tmp_path: Path) -> None:
    sample = tmp_path / "agent.py"
    sample.write_text("from fleetlink.console.edge import EdgeConsole\nfrom ..uplink import x\n")
    targets = [name for _line, name in imports_of("fleetlink.edge.agent", sample)]
    assert targets == ["fleetlink.console.edge", "fleetlink.uplink"]
    assert rank(part_of(targets[0])) > rank(part_of("fleetlink.edge.agent"))
