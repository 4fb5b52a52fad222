"""Every shipped config starts as a real process and does its job, with only addresses (and
state folders) changed by ``--set``: the example configs with the rendered routers of
``deploy/zenoh/local/``, the configs of ``deploy/compose.yaml`` with its cloud router config and
its robots' and healthchecks' commands, and the TLS router templates of ``deploy/zenoh/``
rendered by ``fleetlink zenoh render`` and run by ``fleetlink zenoh router``.

Each fleet is checked end to end: the health endpoints answer (through ``fleetlink probe``,
the containers' healthcheck), simulated robots' records are read back from Kafka with
``fleetlink kafka echo``, and a light-ring command produced to Kafka turns a robot's ring red
(uplink -> WAN -> repeater -> robot).
"""

from __future__ import annotations

import time
import uuid
from pathlib import Path
from typing import Any

import pytest
import yaml

from fleetlink.schemas.typestore import load_typestore
from tests.integration.shipped import Bed, Records, address, answers, endpoint, in_log
from tests.integration.test_commands_harness import RED, CommandProducer
from tests.integration.zenoh_topology import (
    Collector,
    client_config,
    make_bundle,
    opened,
    uplink_config,
)
from tests.paths import DEPLOY

COMMANDS = "fleet.commands.lightring"


def _compose() -> dict[str, Any]:
    data: dict[str, Any] = yaml.safe_load((DEPLOY / "compose.yaml").read_text())
    return data


def _ring_turns_red(bed: Bed, sim_log: Path, robot: str, kafka: tuple[str, str]) -> None:
    """Produce a red light-ring command for ``robot`` until the simulated robot shows it."""
    producer = CommandProducer(kafka[0], kafka[1], load_typestore("jazzy"))
    shown = in_log(sim_log, f"{robot} light ring: red")

    def red_now() -> bool:
        if not shown():
            producer.send(COMMANDS, robot, RED)  # the same command again: applied once per id
            return shown() or _settle(shown, 2.0)
        return True

    bed.wait(red_now, 90, f"{robot}'s light ring red after a command in {COMMANDS}")


def _settle(check: Any, seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if check():
            return True
        time.sleep(0.1)  # ok-sleep: giving one command its time before sending it again
    return False


def _records_arrive(bed: Bed, records: Records, robot: str) -> dict[str, Any]:
    """The first record of ``robot`` that ``fleetlink kafka echo`` prints, decoded."""
    bed.wait(lambda: bool(records.of(robot)), 90, f"a record of {robot} read by fleetlink kafka echo")
    record = records.of(robot)[0]
    assert "error" not in record, record  # decoded with its schema from the registry
    assert record["value"] is not None
    return record


def sets(values: dict[str, str]) -> list[str]:
    """``--set KEY=VALUE`` for each item."""
    return [a for key, value in values.items() for a in ("--set", f"{key}={value}")]


def uplink_sets(kafka: tuple[str, str], cloud: str, metrics: str, console: str, key: Path) -> list[str]:
    return sets(
        {
            "kafka.bootstrap_servers": kafka[0],
            "registry.url": kafka[1],
            "zenoh.connect": f"[{cloud}]",
            "metrics.listen": metrics,
            "console.listen": console,
            "command_signing.key_file": str(key),
        }
    )


def edge_sets(site: str, cloud: str, admin: str, spool: Path) -> list[str]:
    values = {"zenoh.listen": f"[{site}]", "zenoh.connect": f"[{cloud}]", "admin.listen": admin}
    return sets({**values, "spool.dir": str(spool)})


def repeater_sets(site: str, state: Path, key: Path, metrics: str | None = None) -> list[str]:
    values = {
        "zenoh.connect": f"[{site}]",
        "repeater.state_dir": str(state),
        "repeater.command_keys": f"[{key}]",
    }
    return sets(values | ({"metrics.listen": metrics} if metrics else {}))


def command_keys(bed: Bed, folder: Path) -> tuple[Path, Path]:
    """The key pair commands are signed with, made as the docs say: ``fleetlink certs command-key``."""
    made = bed.run("certs", "command-key", str(folder))
    assert made.returncode == 0, made.stderr
    return folder / "command-signing-key.pem", folder / "command-signing.pem"


@pytest.fixture
def kafka(kafka_bootstrap: str, schema_registry_url: str) -> tuple[str, str]:
    return kafka_bootstrap, schema_registry_url


def test_the_example_configs_run_as_shipped(tmp_path: Path, kafka: tuple[str, str]) -> None:
    cloud, site = endpoint(), endpoint()
    admin, metrics, console = address(), address(), address()
    prefix = f"tb4_{uuid.uuid4().hex[:6]}_"
    with Bed(tmp_path) as bed:
        private, public = command_keys(bed, tmp_path / "keys")
        ir = bed.follow("fleet.ir_intensity", *kafka)  # from now on, before any robot
        imu = bed.follow("fleet.imu", *kafka)
        bed.start(
            "cloud-router",
            ["zenoh", "router", "-c", "deploy/zenoh/local/cloud-router.json5", "-l", cloud],
            in_log(tmp_path / "cloud-router.log", "running"),
        )
        bed.start(
            "uplink",
            [
                "uplink",
                "run",
                "-c",
                "deploy/uplink.example.yaml",
                *uplink_sets(kafka, cloud, metrics, console, private),
            ],
            answers(f"http://{metrics}/health"),
        )
        bed.start(
            "edge",
            [
                "edge",
                "run",
                "-c",
                "deploy/edge.example.yaml",
                *edge_sets(site, cloud, admin, tmp_path / "spool"),
            ],
            answers(f"http://{admin}/health"),
        )
        bed.start(
            "repeater",
            [
                "repeater",
                "run",
                "-c",
                "deploy/repeater.example.yaml",
                *repeater_sets(site, tmp_path / "repeater", public, address()),
            ],
            in_log(tmp_path / "repeater.log", "running for site warehouse-a"),
        )
        sim = bed.start(
            "robots",
            ["ros", "sim", "--robots", "2", "--prefix", prefix, "-m", "client", "-e", site],
            in_log(tmp_path / "robots.log", "simulating"),
        )
        robot = f"{prefix}01"
        record = _records_arrive(bed, ir, robot)
        assert len(record["value"]["readings"]) == 7  # the Create 3's seven IR sensors, Avro decoded
        assert "linear_acceleration" in _records_arrive(bed, imu, robot)["value"]
        assert answers(f"http://{console}/console/login")()  # the fleet console is served
        assert answers(f"http://{admin}/console/login")()  # and the site's
        assert answers(f"http://{admin}/metrics")()
        _ring_turns_red(bed, sim, robot, kafka)


def test_the_compose_configs_run_with_their_commands(tmp_path: Path, kafka: tuple[str, str]) -> None:
    services = _compose()["services"]
    cloud, site = endpoint(), endpoint()
    admin, metrics, console = address(), address(), address()
    prefix = f"tb4_{uuid.uuid4().hex[:6]}_"

    def command(name: str) -> list[str]:
        argv: list[str] = services[name]["command"]
        return [a.replace("/etc/fleetlink/", "deploy/compose/") for a in argv]

    def health(name: str, listen: str) -> str:
        test: list[str] = services[name]["healthcheck"]["test"]
        assert test[:3] == ["CMD", "fleetlink", "probe"]
        url: str = test[3]
        return url.replace(url.split("/")[2], listen)

    router = services["cloud-router"]
    config = router["command"][router["command"].index("-c") + 1]
    mount = next(v.split(":")[0] for v in router["volumes"] if v.split(":")[1] == config)
    with Bed(tmp_path) as bed:
        private, public = command_keys(bed, tmp_path / "keys")
        kidnap = bed.follow("fleet.kidnap_status", *kafka)  # from now on, before any robot
        hazards = bed.follow("fleet.hazard_detection", *kafka)
        bed.start(
            "cloud-router",
            ["zenoh", "router", "-c", str((DEPLOY / mount).relative_to(DEPLOY.parent)), "-l", cloud],
            in_log(tmp_path / "cloud-router.log", "running"),
        )
        bed.start(
            "uplink",
            [*command("uplink"), *uplink_sets(kafka, cloud, metrics, console, private)],
            answers(health("uplink", metrics)),
        )
        bed.start(
            "edge",
            [*command("edge"), *edge_sets(site, cloud, admin, tmp_path / "spool")],
            answers(health("edge", admin)),
        )
        bed.start(
            "repeater",
            [*command("repeater"), *repeater_sets(site, tmp_path / "repeater", public)],
            in_log(tmp_path / "repeater.log", "running for site warehouse-a"),
        )
        robots = [a.replace("tcp/edge:7447", site) for a in command("robots")]
        sim = bed.start(
            "robots", [*robots, "--prefix", prefix], in_log(tmp_path / "robots.log", "simulating")
        )
        robot = f"{prefix}05"  # the compose file asks for five robots
        record = _records_arrive(bed, kidnap, robot)
        assert record["value"]["is_kidnapped"] is False
        _records_arrive(bed, hazards, robot)
        _ring_turns_red(bed, sim, robot, kafka)


def test_the_tls_router_templates_run_rendered(tmp_path: Path) -> None:
    bundle = make_bundle(tmp_path / "certs", sites=("site-a",))
    cloud = f"tls/127.0.0.1:{endpoint().rsplit(':', 1)[1]}"
    site = endpoint()
    with Bed(tmp_path) as bed:
        for name, args in (
            ("cloud", ["-l", cloud, "--cert-dir", str(bundle.directory), "--acl-site", "site-a"]),
            ("edge", ["--site", "site-a", "-l", site, "-e", cloud, "--cert-dir", str(bundle.directory)]),
        ):
            out = tmp_path / f"{name}.json5"
            template = str(DEPLOY / "zenoh" / f"{name}-router.json5")
            rendered = bed.run("zenoh", "render", template, *args, "-o", str(out))
            assert rendered.returncode == 0, rendered.stderr
            log = tmp_path / f"{name}-router.log"
            bed.start(f"{name}-router", ["zenoh", "router", "-c", str(out)], in_log(log, "running"))
        heard = Collector()
        with (
            opened(uplink_config(bundle, cloud)) as uplink,
            opened(client_config(site)) as robot,
        ):
            uplink.declare_subscriber("fleetlink/**", heard)

            def reached() -> bool:
                robot.put("fleetlink/site-a/probe", b"x")
                return heard.count("fleetlink/site-a/") > 0

            bed.wait(reached, 30, "a put at the site reaching the cloud over TLS")
            robot.put("fleetlink/site-b/probe", b"x")  # another site's key: the edge's ACL keeps it
            robot.put("0/tb4_01/imu", b"raw")  # raw ROS traffic stays on the site
            robot.put("fleetlink/site-a/done", b"x")
            bed.wait(lambda: heard.count("fleetlink/site-a/done") == 1, 30, "the last put")
        assert heard.count("fleetlink/site-b/") == 0
        assert not [k for k in heard.key_exprs() if not k.startswith("fleetlink/")]
