"""Optional parts: an install without an extra says which extra to install, and runs without it."""

from __future__ import annotations

import importlib
import logging
import sys
import tomllib
from pathlib import Path

import pytest

from fleetlink.cli import main
from fleetlink.cli.edge import console_extensions
from fleetlink.common.extras import MissingExtraError
from fleetlink.demo.cli import missing_parts
from tests.paths import ROOT


def without(monkeypatch: pytest.MonkeyPatch, package: str, *fleetlink_modules: str) -> None:
    """Make ``package`` unimportable and the given fleetlink modules import afresh."""
    monkeypatch.setitem(sys.modules, package, None)  # import raises ModuleNotFoundError
    for name in fleetlink_modules:
        monkeypatch.delitem(sys.modules, name, raising=False)


@pytest.mark.parametrize(
    ("package", "module", "extra"),
    [
        ("jinja2", "fleetlink.console.app", "console"),
        ("quixstreams", "fleetlink.examples.fault_detection.app", "demo"),
    ],
)
def test_a_missing_extra_names_what_to_install(
    monkeypatch: pytest.MonkeyPatch, package: str, module: str, extra: str
) -> None:
    without(monkeypatch, package, module)
    with pytest.raises(MissingExtraError) as info:
        importlib.import_module(module)
    assert f"pip install 'fleetlink[{extra}]'" in str(info.value)
    assert repr(package) in str(info.value)
    assert isinstance(info.value, ImportError)


def test_the_edge_runs_its_admin_api_without_the_console(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    assert len(console_extensions(None, "e1")) == 1
    without(monkeypatch, "jinja2", "fleetlink.console.app", "fleetlink.console.edge")
    with caplog.at_level(logging.INFO):
        assert console_extensions(None, "e1") == []
    assert "pip install 'fleetlink[console]'" in caplog.text


def test_an_uplink_configured_with_a_console_needs_the_extra(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "uplink.yaml"
    path.write_text(
        "kafka: {bootstrap_servers: '127.0.0.1:1'}\nregistry: {url: 'http://127.0.0.1:1'}\n"
        "console: {listen: '127.0.0.1:0'}\n"
    )
    without(monkeypatch, "jinja2", "fleetlink.console.app", "fleetlink.console.uplink")
    assert main(["uplink", "run", "-c", str(path)]) == 1
    err = capsys.readouterr().err
    assert f"{path}: console: the web console needs the package 'jinja2'" in err
    assert "pip install 'fleetlink[console]'" in err


def test_the_demo_says_what_it_lacks_before_starting_anything(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    assert missing_parts() is None
    without(monkeypatch, "quixstreams", "fleetlink.examples.fault_detection.app")
    assert main(["demo", "--workdir", str(tmp_path / "demo")]) == 2
    assert not (tmp_path / "demo").exists()
    missing = missing_parts()
    assert missing is not None
    assert "pip install 'fleetlink[demo]'" in missing


def test_an_edge_install_carries_no_console_or_demo_packages() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    core = " ".join(project["dependencies"])
    for package in ("quixstreams", "jinja2", "pytest"):
        assert package not in core
    extras = project["optional-dependencies"]
    assert any(d.startswith("jinja2") for d in extras["console"])
    assert any(d.startswith("quixstreams") for d in extras["demo"])
    assert "fleetlink[console,demo]" in extras["dev"]
