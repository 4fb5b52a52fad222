"""The test bed of the security rows: two sites on the production router configs, an honest one
streaming and a rogue one attacking.

::

    site A: generator tb4_01 -> site-a router (edge-router.json5) -> edge A process
                    \\                          \\ mTLS, cert edge-site-a
    sim robot tb4_01 <- repeater A              cloud router (cloud-router.json5, per-site ACL)
                                                 / mTLS, cert edge-site-b       \\ mTLS, cert fleetlink-uplink
    site B: sim robots tb4_01, tb4_09 <- repeater B <- site-b router       uplink process -> Kafka, registry
            rogue process (site B's certificate, or a client on site B's network)

Routers, repeaters and simulated robots run in the test process; the uplink, the edge and the
rogue (``tests.fault.rogue_site``) are processes of their own. Every name is unique to the run.
"""

from __future__ import annotations

import json
import subprocess
import sys
import urllib.request
import uuid
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import yaml
from prometheus_client.parser import text_string_to_metric_families

from fleetlink.common.certs import UPLINK_NAME, CertBundle, generate_bundle
from fleetlink.common.command_keys import write_command_key
from fleetlink.repeater.config import RepeaterConfig
from fleetlink.repeater.service import Repeater
from fleetlink.roswire.sim.fleet import Fleet
from tests.fault.e2e_processes import ROOT, Count, Generator, Process, count, read_all
from tests.fault.stats_file import read_stats
from tests.helpers import free_port, wait_until
from tests.integration.e2e_stack import TopicReader, headers
from tests.integration.test_commands_harness import (
    CommandProducer,
    LedLog,
    irobot_store,
    lightring_mapping,
    robot_config,
)
from tests.integration.zenoh_topology import Edge, opened, routers_connected, tls_cloud, tls_edge
from tests.paths import IROBOT

STRING = "std_msgs/msg/String"
SITES = ("site-a", "site-b")


@dataclass
class Topics:
    run: str

    @property
    def chat(self) -> str:
        """Site A's data (and the fleet's: site B may write here too)."""
        return f"sec.{self.run}.chat"

    @property
    def b_own(self) -> str:
        return f"sec.{self.run}.b"

    @property
    def a_private(self) -> str:
        """Only site A's policy allows it."""
        return f"site-a.{self.run}.private"

    @property
    def other(self) -> str:
        """No site's policy allows it."""
        return f"other.{self.run}.x"

    @property
    def commands(self) -> str:
        return f"cmd.{self.run}.lightring"

    @property
    def registrations(self) -> str:
        return f"reg.{self.run}"

    @property
    def dead_letter(self) -> str:
        return f"dlq.{self.run}"

    @property
    def refused(self) -> str:
        return f"refused.{self.run}"

    @property
    def status(self) -> str:
        return f"status.{self.run}"

    @property
    def command_dead_letter(self) -> str:
        return f"cmd-dlq.{self.run}"

    def owned_by_fleetlink(self) -> list[str]:
        return [
            self.commands,
            self.status,
            self.command_dead_letter,
            self.refused,
            f"fleetlink.{self.run}.x",
            f"_{self.run}.x",
        ]


@dataclass
class SecurityBed:
    tmp: Path
    bootstrap: str
    registry_url: str
    topics: Topics
    bundle: CertBundle
    cloud_endpoint: str
    site_a: Edge
    site_b: Edge
    uplink: Process
    edge_a: Process
    stats_file: Path
    metrics_url: str
    repeater_a: Repeater
    repeater_b: Repeater
    leds_a: LedLog
    leds_b: LedLog
    generator: Generator
    reader: TopicReader
    commands: CommandProducer
    processes: list[Process] = field(default_factory=list)

    # -- the rogue -----------------------------------------------------------------------------

    def rogue(self, attack: str, *, via: str = "cloud", **spec: Any) -> dict[str, Any]:
        """Run one attack as a separate process holding only site B's keys; its JSON answer."""
        where = (
            ["--cloud", self.cloud_endpoint, "--certs", str(self.tmp / "site-b-keys")]
            if via == "cloud"
            else ["--site-router", self.site_b.endpoint]
        )
        spec = {"ready_key": "fleetlink/site-b/ingest/edge-b", **spec}
        proc = subprocess.run(
            [sys.executable, "-m", "tests.fault.rogue_site", attack, "--spec", json.dumps(spec), *where],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=180,
            check=False,
        )
        if proc.returncode != 0:
            raise AssertionError(f"the rogue failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
        result: dict[str, Any] = json.loads(proc.stdout.strip().splitlines()[-1])
        print(f"\nrogue {attack}: {json.dumps(result)[:1500]}")
        return result

    # -- what the uplink counted ---------------------------------------------------------------

    def counter(self, name: str, **labels: str) -> float:
        with urllib.request.urlopen(self.metrics_url, timeout=5) as response:
            text = response.read().decode()
        total = 0.0
        for family in text_string_to_metric_families(text):
            for sample in family.samples:
                if sample.name == name and all(sample.labels.get(k) == v for k, v in labels.items()):
                    total += sample.value
        return total

    # -- the honest site -----------------------------------------------------------------------

    def stats(self) -> dict[str, Any]:
        return read_stats(self.stats_file)[1]

    def honest_site_kept_flowing(self) -> Count:
        """Pause site A's generator, wait until its edge drained, count what reached Kafka: every
        value once at least, nothing else, every record from site A; then stream on."""
        sent = self.generator.pause()

        def drained() -> bool:
            stats = self.stats()
            buffer = stats.get("streams", {}).get("durable", {}).get("buffer", {})
            return bool(stats.get("processor", {}).get("samples", 0) >= sent and buffer.get("depth") == 0)

        self.wait(drained, 60, f"site A's {sent} records spooled and acknowledged")
        msgs = read_all(self.reader, self.topics.chat, sent)
        result = count(self.reader, msgs, sent)
        print(f"\nsite A: {sent} sent: {result}")
        assert {headers(m).get("fleetlink.site") for m in msgs} == {"site-a"}
        self.generator.start()
        return result

    def wait(self, condition: Any, timeout: float, what: str) -> None:
        try:
            wait_until(condition, timeout, interval=0.1, message=what)
        except AssertionError as exc:
            logs = "\n".join(f"--- {p.log.name}\n{p.tail()}" for p in self.processes)
            raise AssertionError(f"{exc}\n{logs}") from None


def _yaml(path: Path, data: dict[str, Any]) -> Path:
    path.write_text(yaml.safe_dump(data))
    return path


def _tls(bundle: CertBundle, name: str) -> dict[str, Any]:
    files = bundle[name]
    return {
        "transport/link/tls/root_ca_certificate": str(bundle.ca_certificate),
        "transport/link/tls/enable_mtls": True,
        "transport/link/tls/connect_certificate": str(files.certificate),
        "transport/link/tls/connect_private_key": str(files.key),
    }


def uplink_yaml(tmp: Path, bed: dict[str, Any]) -> Path:
    t: Topics = bed["topics"]
    return _yaml(
        tmp / "uplink.yaml",
        {
            "kafka": {"bootstrap_servers": bed["bootstrap"], "client_id": f"uplink-{t.run}", "linger": "2ms"},
            "registry": {"url": bed["registry_url"]},
            "zenoh": {
                "mode": "client",
                "connect": [bed["cloud"]],
                "overrides": _tls(bed["bundle"], UPLINK_NAME),
            },
            "topics": {
                "dead_letter": t.dead_letter,
                "registrations": t.registrations,
                "command_dead_letter": t.command_dead_letter,
                "command_status": t.status,
                "refused": t.refused,
            },
            "policy": {
                "default": {"topics": [f"sec.{t.run}.*"]},
                "sites": {"site-a": {"topics": [f"sec.{t.run}.*", f"{{site}}.{t.run}.*"]}},
            },
            "commands": [lightring_mapping(t.commands, period="1s", lease="8s")],
            "command_signing": {"key_file": str(bed["keys"][0])},
            "metrics": {"listen": f"127.0.0.1:{bed['metrics_port']}"},
        },
    )


def edge_yaml(tmp: Path, t: Topics, router: str, site: str, edge_id: str, **extra: Any) -> Path:
    return _yaml(
        tmp / f"edge-{site}.yaml",
        {
            "site": site,
            "edge_id": edge_id,
            "zenoh": {"mode": "client", "connect": [router]},
            "robot_types": {
                "tb4": {
                    "match": "/tb4_*",
                    "mappings": [{"name": "chat", "from": "/{robot}/chatter", "to": t.chat, "type": STRING}],
                }
            },
            "spool": {"dir": str(tmp / f"spool-{site}"), "segment_bytes": "1MiB", "max_bytes": "64MiB"},
            "registration": {"grace_period": "30s"},
            "wan": {"batch_max_records": 100, "linger": "10ms", "ack_timeout": "10s", "max_in_flight": 1},
            "topics": {"dead_letter": t.dead_letter, "registrations": t.registrations},
            **extra,
        },
    )


def repeater(site: Edge, state: Path, public_key: Path) -> Repeater:
    return Repeater(
        RepeaterConfig.model_validate(
            {
                "repeater": {
                    "site": site.site,
                    "state_dir": str(state),
                    "id": f"rep-{site.site}",
                    "heartbeat": "300ms",
                    "command_keys": [str(public_key)],
                },
                "ros": {"distro": "jazzy", "message_paths": [str(IROBOT)]},
                "zenoh": {"mode": "client", "connect": [site.endpoint]},
            }
        )
    )


def _site_b_keys(bundle: CertBundle, into: Path) -> None:
    """What the rogue holds: the CA certificate and site B's edge identity, nothing else."""
    into.mkdir()
    for path in (bundle.ca_certificate, bundle["edge-site-b"].certificate, bundle["edge-site-b"].key):
        (into / path.name).write_bytes(path.read_bytes())


@contextmanager
def security_bed(tmp: Path, bootstrap: str, registry_url: str) -> Iterator[SecurityBed]:
    run = uuid.uuid4().hex[:8]
    topics = Topics(run)
    bundle = generate_bundle(tmp / "certs", now=datetime.now(UTC), sites=SITES)
    keys = write_command_key(tmp / "command-keys")
    _site_b_keys(bundle, tmp / "site-b-keys")
    ts = irobot_store()
    with ExitStack() as stack:
        cloud = stack.enter_context(tls_cloud(bundle, SITES))
        site_a = stack.enter_context(tls_edge(bundle, "site-a", cloud.endpoint))
        site_b = stack.enter_context(tls_edge(bundle, "site-b", cloud.endpoint))
        wait_until(
            lambda: routers_connected(site_a.session) == 1 and routers_connected(site_b.session) == 1,
            15,
            message="both site routers linked to the cloud over mTLS",
        )
        metrics_port = free_port()
        config = {
            "topics": topics,
            "bootstrap": bootstrap,
            "registry_url": registry_url,
            "cloud": cloud.endpoint,
            "bundle": bundle,
            "keys": keys,
            "metrics_port": metrics_port,
        }
        processes: list[Process] = []
        stack.callback(lambda: [p.terminate(10) for p in processes if p.alive()])
        uplink = Process("uplink", ["uplink", "run", "-c", str(uplink_yaml(tmp, config))], tmp / "uplink.log")
        processes.append(uplink.start())
        stats = tmp / "edge-a-stats.json"
        edge_a = Process(
            "edge-a",
            [
                "edge",
                "run",
                "-c",
                str(edge_yaml(tmp, topics, site_a.endpoint, "site-a", "edge-a")),
                "--stats-file",
                str(stats),
                "--stats-interval",
                "0.2",
            ],
            tmp / "edge-a.log",
        )
        processes.append(edge_a.start())
        rep_a = stack.enter_context(repeater(site_a, tmp / "rep-a", keys[1]))
        rep_b = stack.enter_context(repeater(site_b, tmp / "rep-b", keys[1]))
        leds_a, leds_b = LedLog(), LedLog()
        robots_a = stack.enter_context(
            Fleet(robot_config(site_a.endpoint), ts, robots=0, rate=1.0, on_led=leds_a)
        )
        robots_b = stack.enter_context(
            Fleet(robot_config(site_b.endpoint), ts, robots=0, rate=1.0, on_led=leds_b)
        )
        robots_a.add_robot("tb4_01")
        robots_b.add_robot("tb4_01")  # the rogue site's own robot of that name
        robots_b.add_robot("tb4_09")
        generator = Generator(site_a.endpoint, rate=200.0)
        stack.callback(generator.close)
        bed = SecurityBed(
            tmp,
            bootstrap,
            registry_url,
            topics,
            bundle,
            cloud.endpoint,
            site_a,
            site_b,
            uplink,
            edge_a,
            stats,
            f"http://127.0.0.1:{metrics_port}/metrics",
            rep_a,
            rep_b,
            leds_a,
            leds_b,
            generator,
            TopicReader(bootstrap, registry_url),
            CommandProducer(bootstrap, registry_url, ts),
            processes,
        )
        bed.wait(lambda: "uplink running" in uplink.tail(), 60, "the uplink started")
        generator.wait_subscribed(60)
        generator.start()
        bed.wait(
            lambda: len(bed.reader.consume(topics.registrations, 0, lambda ms: len(ms) >= 1, 1.0)) >= 1,
            60,
            "site A registered tb4_01 through the uplink",
        )
        yield bed


__all__ = ["SITES", "STRING", "SecurityBed", "Topics", "opened", "security_bed"]
