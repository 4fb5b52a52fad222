"""Deploy files are tested artefacts: configs validate, compose and units hang together."""

from __future__ import annotations

import configparser
import re
import shlex
from pathlib import Path

import pytest
import yaml

from fleetlink.cli import build_parser
from fleetlink.cli.validate import validate_file
from tests.paths import ROOT

DEPLOY = ROOT / "deploy"


@pytest.mark.parametrize(
    "path",
    sorted(p for p in DEPLOY.rglob("*.yaml") if p.name != "compose.yaml"),
    ids=lambda p: str(p.relative_to(DEPLOY)),
)
def test_every_fleetlink_config_in_deploy_validates(path: Path) -> None:
    kind, _ = validate_file(path)
    assert kind in ("edge", "uplink", "repeater")


def _commands() -> set[str]:
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    return set(sub.choices or {})


def test_compose_is_consistent() -> None:
    compose = yaml.safe_load((DEPLOY / "compose.yaml").read_text())
    services = compose["services"]
    assert {"kafka", "registry", "cloud-router", "uplink", "edge", "repeater", "robots"} <= set(services)
    for name, service in services.items():
        assert "image" in service or "build" in service, name
        for dep in service.get("depends_on", []):
            assert dep in services, f"{name} depends on unknown service {dep}"
        for volume in service.get("volumes", []):
            source = volume.split(":")[0]
            if source.startswith("."):
                assert (DEPLOY / source).exists(), f"{name}: {source} does not exist"
        command = service.get("command")
        if service.get("image", "").startswith("localhost/fleetlink"):
            assert command[0] in _commands(), f"{name}: fleetlink has no {command[0]!r} command"
    for named in (v.split(":")[0] for s in services.values() for v in s.get("volumes", [])):
        if not named.startswith((".", "/")):
            assert named in compose.get("volumes", {}), f"named volume {named} is not declared"


def test_containerfile_installs_every_package() -> None:
    text = (DEPLOY / "Containerfile").read_text()
    pyproject = (ROOT / "pyproject.toml").read_text()
    include = re.search(r"include = \[(.*?)\]", pyproject)
    assert include is not None
    packages = [p.strip(' "*') for p in include.group(1).split(",")]
    for package in packages:
        assert f"COPY {package} ./{package}" in text, f"Containerfile misses {package}"


@pytest.mark.parametrize("unit", sorted((DEPLOY / "systemd").glob("*.service")), ids=lambda p: p.name)
def test_systemd_units_run_real_commands(unit: Path) -> None:
    parser = configparser.ConfigParser(strict=False, interpolation=None)
    parser.read_string(unit.read_text())
    exec_start = shlex.split(parser["Service"]["ExecStart"])
    assert exec_start[0].endswith("/fleetlink")
    assert exec_start[1] in _commands()
    assert parser["Service"]["KillSignal"] == "SIGTERM"
    validate = shlex.split(parser["Service"]["ExecStartPre"])
    assert validate[1] == "validate"
    assert validate[2] == exec_start[-1]  # the same config file is validated first
