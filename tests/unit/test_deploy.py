"""Deploy files are tested artefacts: configs validate as start-up would, rendered router configs
are what their command renders, compose and the Containerfile hang together.

No container engine runs here, so compose.yaml and the Containerfile are checked by reading
them: every mount is a path of this repository, every state folder is on a named volume the
image's user can write, Kafka and the registry keep their state, dependencies wait for
healthchecks, and every fleetlink command in them is one the real parser takes.
"""

from __future__ import annotations

import configparser
import re
import shlex
import tomllib
from pathlib import Path
from typing import Any

import pytest
import yaml

from fleetlink.cli import build_parser
from fleetlink.cli.validate import validate_file
from fleetlink.common.command_keys import write_command_key
from fleetlink.common.errors import ConfigError
from fleetlink.common.zenoh_options import load_zenoh_file
from tests.paths import DEPLOY, ROOT

FLEETLINK_CONFIGS = sorted(p for p in DEPLOY.rglob("*.yaml") if p.name != "compose.yaml")
RENDERED = sorted(p for p in DEPLOY.rglob("*.json5") if p.read_text().startswith("// Rendered from "))


def _compose() -> dict[str, Any]:
    data: dict[str, Any] = yaml.safe_load((DEPLOY / "compose.yaml").read_text())
    return data


def _fleetlink_services() -> dict[str, dict[str, Any]]:
    return {
        n: s
        for n, s in _compose()["services"].items()
        if s.get("image", "").startswith("localhost/fleetlink")
    }


@pytest.mark.parametrize("path", FLEETLINK_CONFIGS, ids=lambda p: str(p.relative_to(DEPLOY)))
def test_every_fleetlink_config_in_deploy_validates(path: Path) -> None:
    kind, _ = validate_file(path, host_checks=False)
    assert kind in ("edge", "uplink", "repeater")


def _key_sets(name: str, keys: tuple[Path, Path]) -> list[str]:
    """Where the command signing keys are: ``fleetlink certs command-key`` makes them first."""
    private, public = keys
    return {
        "uplink": [f"command_signing.key_file={private}"],
        "repeater": [f"repeater.command_keys=[{public}]"],
    }.get(name, [])


@pytest.fixture(scope="module")
def command_keys(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    return write_command_key(tmp_path_factory.mktemp("keys"))


@pytest.mark.parametrize("name", ["edge", "uplink", "repeater"])
def test_example_configs_pass_the_start_up_checks_as_shipped(
    name: str, command_keys: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(ROOT)  # their relative paths are the repository's
    monkeypatch.delenv("FLEETLINK_SET", raising=False)
    validate_file(DEPLOY / f"{name}.example.yaml", sets=_key_sets(name, command_keys))


@pytest.mark.parametrize(
    ("name", "key"), [("uplink", "command_signing.key_file"), ("repeater", "repeater.command_keys[0]")]
)
def test_a_missing_command_key_says_how_to_make_it(name: str, key: str, tmp_path: Path) -> None:
    sets = [f"repeater.state_dir={tmp_path}"] if name == "repeater" else []
    with pytest.raises(ConfigError) as info:
        validate_file(DEPLOY / "compose" / f"{name}.yaml", sets=sets)
    assert f"{key} (line" in str(info.value)
    assert "fleetlink certs command-key DIR" in str(info.value)


@pytest.mark.parametrize("name", ["edge", "uplink", "repeater"])
def test_compose_configs_pass_the_start_up_checks_with_their_volumes(
    name: str, command_keys: tuple[Path, Path], tmp_path: Path
) -> None:
    # inside the container, the state folders and keys are named volumes; here, temporary ones
    state = {"edge": [f"spool.dir={tmp_path}"], "repeater": [f"repeater.state_dir={tmp_path}"]}
    sets = [*state.get(name, []), *_key_sets(name, command_keys)]
    validate_file(DEPLOY / "compose" / f"{name}.yaml", sets=sets)


@pytest.mark.parametrize("path", RENDERED, ids=lambda p: str(p.relative_to(DEPLOY)))
def test_rendered_router_configs_are_what_their_command_renders(
    path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    lines = path.read_text().splitlines()
    command = shlex.split(lines[1].removeprefix("//").strip())
    assert command[:3] == ["fleetlink", "zenoh", "render"]
    argv = command[1:]
    if "-o" in argv:  # render to stdout, compare with the file
        at = argv.index("-o")
        assert ROOT / argv[at + 1] == path, "the header names another output file"
        del argv[at : at + 2]
    monkeypatch.chdir(ROOT)
    parser = build_parser()
    args = parser.parse_args(argv)
    assert args.handler(args) == 0
    rendered = capsys.readouterr().out.splitlines()
    assert rendered[3:] == lines[3:], f"{path} differs from its template: render it again"
    load_zenoh_file(path)  # concrete: no placeholder left, and Zenoh's parser takes it


def test_no_rendered_file_is_missing() -> None:
    names = {str(p.relative_to(DEPLOY)) for p in RENDERED}
    assert {
        "zenoh/local/edge-router.json5",
        "zenoh/local/cloud-router.json5",
        "compose/cloud-router.json5",
    } <= names


def _volume_sources(service: dict[str, Any]) -> list[str]:
    return [v.split(":")[0] for v in service.get("volumes", [])]


def test_compose_mounts_only_repository_paths_and_declared_volumes() -> None:
    compose = _compose()
    for name, service in compose["services"].items():
        for source in _volume_sources(service):
            if source.startswith("."):
                path = (DEPLOY / source).resolve()
                assert path.is_relative_to(ROOT), f"{name}: {source} is outside the repository"
                assert path.exists(), f"{name}: {source} does not exist"
            else:
                assert not source.startswith("/"), f"{name}: {source} is a host path"
                assert source in compose.get("volumes", {}), f"{name}: named volume {source} is not declared"


def test_compose_dependencies_wait_for_healthchecks() -> None:
    services = _compose()["services"]
    for name, service in services.items():
        depends = service.get("depends_on", {})
        assert isinstance(depends, dict), f"{name}: depends_on is a list (it would not wait for health)"
        for dep, condition in depends.items():
            assert dep in services, f"{name} depends on unknown service {dep}"
            if services[dep].get("restart") == "no":  # a one-shot job: waited for until it is done
                assert condition == {"condition": "service_completed_successfully"}, f"{name} -> {dep}"
                continue
            assert condition == {"condition": "service_healthy"}, f"{name} -> {dep}"
            assert "healthcheck" in services[dep], f"{dep} has no healthcheck, {name} waits for it"


def test_compose_commands_are_real_fleetlink_commands() -> None:
    parser = build_parser()
    for name, service in _fleetlink_services().items():
        args = parser.parse_args(service["command"])
        assert getattr(args, "handler", None) is not None, f"{name}: {service['command']}"
        check = service.get("healthcheck", {}).get("test", [])
        if check[:2] == ["CMD", "fleetlink"]:
            assert parser.parse_args(check[2:]).handler is not None, f"{name}: {check}"


def test_kafka_and_the_registry_keep_their_state() -> None:
    services = _compose()["services"]
    kafka = services["kafka"]
    log_dirs = kafka["environment"]["KAFKA_LOG_DIRS"]
    assert any(v.endswith(f":{log_dirs}") and not v.startswith(".") for v in kafka["volumes"])
    registry = services["registry"]["environment"]
    # Apicurio keeps its schemas in a Kafka topic, so they live (and die) with Kafka's volume
    assert registry["APICURIO_STORAGE_KIND"] == "kafkasql"
    assert registry["APICURIO_KAFKASQL_BOOTSTRAP_SERVERS"] == "kafka:9092"


def _service_config(service: dict[str, Any]) -> tuple[Path, dict[str, Any]]:
    command = service["command"]
    inside = command[command.index("-c") + 1]
    mount = next(v for v in service["volumes"] if v.split(":")[1] == inside)
    path = (DEPLOY / mount.split(":")[0]).resolve()
    return path, yaml.safe_load(path.read_text())


def _containerfile() -> str:
    return (DEPLOY / "Containerfile").read_text()


def test_volumes_written_by_fleetlink_are_folders_the_image_user_owns() -> None:
    containerfile = _containerfile()
    user = re.findall(r"^USER (\S+)", containerfile, re.MULTILINE)[-1]
    made = re.search(r"mkdir -p ([^&]+)&&\s*chown -R (\S+) ([^\n]+)", containerfile)
    assert made is not None, "the Containerfile makes no state folders"
    folders, owner, owned = made.group(1).split(), made.group(2), made.group(3).split()
    assert owner == user
    # a named volume starts as a copy of the image's folder: it must exist there, owned by the user
    for name, service in _fleetlink_services().items():
        for volume in service.get("volumes", []):
            source, target, *mode = volume.split(":")
            if source.startswith(".") or mode == ["ro"]:
                continue
            assert target in folders, f"{name}: {target} is not made in the image"
            assert any(target.startswith(o) for o in owned), f"{name}: {target} is not {user}'s"
    services = _fleetlink_services()
    state = {"edge": ("spool", "dir"), "repeater": ("repeater", "state_dir")}
    for name, (section, key) in state.items():
        _path, config = _service_config(services[name])
        folder = config[section][key]
        assert folder in folders, f"{name}: {folder} is not made in the image"
        assert any(folder.startswith(o) for o in owned), f"{name}: {folder} is not {user}'s"
        assert any(v.endswith(f":{folder}") and not v.startswith(".") for v in services[name]["volumes"]), (
            f"{name}: {folder} is on no named volume"
        )


def test_console_and_metrics_are_on_and_published() -> None:
    services = _fleetlink_services()
    _path, edge = _service_config(services["edge"])
    _path, uplink = _service_config(services["uplink"])
    published = {p.split(":")[-1] for s in services.values() for p in s.get("ports", [])}
    for listen in (edge["admin"]["listen"], uplink["metrics"]["listen"], uplink["console"]["listen"]):
        host, port = listen.rsplit(":", 1)
        assert host == "0.0.0.0", listen  # reachable from outside the container
        assert port in published, f"{listen} is not published"
        assert port in " ".join(re.findall(r"^EXPOSE (.*)$", _containerfile(), re.MULTILINE)).split()


def test_the_cloud_router_gets_a_concrete_config() -> None:
    router = _compose()["services"]["cloud-router"]
    config = router["command"][router["command"].index("-c") + 1]
    mount = next(v for v in router["volumes"] if v.split(":")[1] == config)
    load_zenoh_file((DEPLOY / mount.split(":")[0]).resolve())


def test_containerfile_installs_every_package() -> None:
    text = _containerfile()
    pyproject = (ROOT / "pyproject.toml").read_text()
    include = re.search(r"include = \[(.*?)\]", pyproject)
    assert include is not None
    packages = [p.strip(' "*') for p in include.group(1).split(",")]
    for package in packages:
        assert f"COPY {package} ./{package}" in text, f"Containerfile misses {package}"


def test_containerfile_can_build_the_native_extensions() -> None:
    text = _containerfile()
    build = text.split("\nFROM ", 2)[1]  # the build stage, up to the runtime image
    extensions = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools-rust"][
        "ext-modules"
    ]
    assert extensions, "no native extension declared"
    for extension in extensions:
        folder = Path(extension["path"]).parts[0]
        assert f"COPY {folder} ./{folder}" in build, f"the build stage misses {folder}/"
    assert "rustup" in build, "the build stage has no Rust toolchain for setuptools-rust"
    assert "build-essential" in build, "the build stage has no C toolchain (linker)"


@pytest.mark.parametrize("unit", sorted((DEPLOY / "systemd").glob("*.service")), ids=lambda p: p.name)
def test_systemd_units_run_real_commands(unit: Path) -> None:
    parser = configparser.ConfigParser(strict=False, interpolation=None)
    parser.read_string(unit.read_text())
    exec_start = shlex.split(parser["Service"]["ExecStart"])
    assert exec_start[0].endswith("/fleetlink")
    assert build_parser().parse_args(exec_start[1:]).handler is not None
    assert parser["Service"]["KillSignal"] == "SIGTERM"
    validate = shlex.split(parser["Service"]["ExecStartPre"])
    assert validate[1] == "validate"
    assert validate[2] == exec_start[-1]  # the same config file is validated first
