"""Harness shared by the command tests (no tests of its own): a cloud router, sites behind TCP
relays, an uplink with command mappings, repeaters, simulated robots, and Kafka helpers (the
stock Avro serializer and deserializer).

Everything is real: Zenoh routers opened from the shipped development templates
(``deploy/zenoh/cloud-router-dev.json5``: only ``fleetlink/**`` crosses the cloud, so raw ROS
traffic stays on its site; ``edge-router-dev.json5`` for the sites), Kafka and the registry from
the session fixtures, rmw_zenoh-style robots from ``roswire.sim`` (gossip off, so nothing
bypasses the relays). Each test makes its own topics, consumer group and state directory.
"""

from __future__ import annotations

import atexit
import json
import shutil
import tempfile
import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import zenoh
from confluent_kafka import Consumer, Producer
from confluent_kafka.admin import AdminClient, NewTopic
from confluent_kafka.schema_registry import SchemaRegistryClient
from confluent_kafka.schema_registry.avro import AvroDeserializer, AvroSerializer
from confluent_kafka.serialization import MessageField, SerializationContext

from fleetlink.common.command_keys import write_command_key
from fleetlink.common.zenoh_configs import render_router_config
from fleetlink.localstack.relay import TcpRelay
from fleetlink.repeater.config import RepeaterConfig
from fleetlink.repeater.service import Repeater
from fleetlink.roswire.sim.fleet import Fleet
from fleetlink.roswire.sim.model import LedState
from fleetlink.schemas.avro_schema import avro_schema
from fleetlink.schemas.registry import on_a_live_connection
from fleetlink.schemas.typestore import load_typestore
from fleetlink.uplink.config import UplinkConfig
from fleetlink.uplink.service import Uplink
from tests.helpers import free_port, wait_until, zenoh_peer_config
from tests.paths import IROBOT

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

DEPLOY = Path(__file__).resolve().parents[2] / "deploy" / "zenoh"
LIGHTRING = "irobot_create_msgs/msg/LightringLeds"
RED, GREEN, BLUE, YELLOW = (255, 0, 0), (0, 255, 0), (0, 0, 255), (255, 255, 0)
REGISTRATION_SCHEMA = {
    "type": "record",
    "name": "RobotRegistration",
    "namespace": "fleetlink",
    "fields": [
        {"name": "robot", "type": "string"},
        {"name": "robot_type", "type": "string"},
        {"name": "site", "type": "string"},
        {"name": "edge_id", "type": "string"},
        {"name": "event", "type": "string"},
        {"name": "timestamp", "type": "long"},
    ],
}


def distinct(items: list[str]) -> list[str]:
    """``items`` without repeats, in first-seen order (status records are at-least-once)."""
    return list(dict.fromkeys(items))


def irobot_store() -> Typestore:
    return load_typestore("jazzy", [IROBOT])


def uid() -> str:
    return uuid.uuid4().hex[:8]


def robot_config(endpoint: str) -> zenoh.Config:
    conf = zenoh_peer_config(endpoint)
    conf.insert_json5("scouting/gossip/enabled", "false")
    return conf


# -- Zenoh: cloud router, sites behind relays ------------------------------------------------


@dataclass
class Site:
    name: str
    router: Router
    relay: TcpRelay

    @property
    def endpoint(self) -> str:
        return self.router.endpoint


class Router:
    """A router-mode session opened from one of the shipped templates in deploy/zenoh/."""

    def __init__(self, template: str, *, site: str | None = None, connect: tuple[str, ...] = ()) -> None:
        self.port = free_port()
        self._config = render_router_config(
            DEPLOY / template, site=site, listen=[self.endpoint], connect=list(connect)
        )
        self.session: zenoh.Session | None = None

    @property
    def endpoint(self) -> str:
        return f"tcp/127.0.0.1:{self.port}"

    def __enter__(self) -> Router:
        self.session = zenoh.open(self._config)
        return self

    def __exit__(self, *exc: object) -> None:
        if self.session is not None:
            self.session.close()
            self.session = None


class Wan:
    """A cloud router and any number of site routers, each linked through its own TcpRelay."""

    def __init__(self) -> None:
        self.cloud = Router("cloud-router-dev.json5")
        self.sites: dict[str, Site] = {}
        self._stack = ExitStack()

    def __enter__(self) -> Wan:
        self._stack.enter_context(self.cloud)
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.close()

    def add_site(self, name: str) -> Site:
        relay = self._stack.enter_context(TcpRelay(self.cloud.port))
        router = self._stack.enter_context(
            Router("edge-router-dev.json5", site=name, connect=(relay.endpoint,))
        )
        site = Site(name, router, relay)
        self.sites[name] = site
        _wait_linked(self.cloud.endpoint, router.endpoint)
        return site


def _wait_linked(cloud: str, site: str) -> None:
    """Wait until a token declared at the site is seen from the cloud (the WAN link is up)."""
    key = f"fleetlink/probe/{uid()}"
    with (
        zenoh.open(zenoh_peer_config(site, "client")) as at_site,
        zenoh.open(zenoh_peer_config(cloud, "client")) as at_cloud,
    ):
        token = at_site.liveliness().declare_token(key)
        wait_until(
            lambda: any(r.ok is not None for r in at_cloud.liveliness().get(key, timeout=0.5)),
            timeout=15,
            message="site router linked to the cloud router",
        )
        token.undeclare()


# -- Kafka -----------------------------------------------------------------------------------


def create_topics(bootstrap: str, *names: str, partitions: int = 1) -> None:
    admin = AdminClient({"bootstrap.servers": bootstrap})
    new = [NewTopic(n, num_partitions=partitions, replication_factor=1) for n in names]
    futures = admin.create_topics(new)
    for future in futures.values():
        future.result(20)


class CommandProducer:
    """Produces LightringLeds commands the way a stream-processing app does: stock AvroSerializer,
    the schema fleetlink derives from the ROS definition, key = robot."""

    def __init__(self, bootstrap: str, registry_url: str, typestore: Typestore) -> None:
        self.client = SchemaRegistryClient({"url": registry_url})
        self.schema = avro_schema(typestore, LIGHTRING, "jazzy")
        self._serializer = AvroSerializer(self.client, json.dumps(self.schema), to_dict=lambda obj, _ctx: obj)
        self._producer = Producer({"bootstrap.servers": bootstrap, "linger.ms": 0})

    def value(self, topic: str, colour: tuple[int, int, int]) -> bytes:
        datum = {
            "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
            "leds": [{"red": colour[0], "green": colour[1], "blue": colour[2]}] * 6,
            "override_system": True,
        }
        out = self._serializer(datum, SerializationContext(topic, MessageField.VALUE))
        assert isinstance(out, bytes)
        return out

    def send(
        self,
        topic: str,
        robot: str | None,
        colour: tuple[int, int, int] = RED,
        *,
        command_id: str | None = None,
        timestamp_ms: int | None = None,
        raw_value: bytes | None = None,
    ) -> float:
        """Produce one command and wait for Kafka's ack; returns the wall time it was produced."""
        value = raw_value if raw_value is not None else self.value(topic, colour)
        headers = [("fleetlink-command-id", command_id.encode())] if command_id else []
        errors: list[Any] = []
        sent = time.time()
        self._producer.produce(
            topic,
            key=robot.encode() if robot else None,
            value=value,
            headers=headers,
            timestamp=timestamp_ms or 0,
            on_delivery=lambda err, _m: errors.append(err),
        )
        self._producer.flush(10)
        assert errors == [None], errors
        return sent

    def register(self, topic: str, robot: str, site: str, event: str = "registered") -> None:
        serializer = AvroSerializer(self.client, json.dumps(REGISTRATION_SCHEMA), to_dict=lambda o, _c: o)
        datum = {
            "robot": robot,
            "robot_type": "turtlebot4",
            "site": site,
            "edge_id": f"edge-{site}",
            "event": event,
            "timestamp": int(time.time() * 1000),
        }
        value = serializer(datum, SerializationContext(topic, MessageField.VALUE))
        self._producer.produce(topic, key=robot.encode(), value=value)
        self._producer.flush(10)


class TopicLog:
    """Reads a topic from the beginning in a thread; values decoded with the stock deserializer
    (``avro=True``) or kept raw."""

    def __init__(self, bootstrap: str, registry_url: str, topic: str, *, avro: bool = True) -> None:
        self.topic = topic
        self._consumer = Consumer(
            {
                "bootstrap.servers": bootstrap,
                "group.id": f"log-{uid()}",
                "auto.offset.reset": "earliest",
                "enable.auto.commit": False,
            }
        )
        self._deserializer = AvroDeserializer(SchemaRegistryClient({"url": registry_url})) if avro else None
        self.records: list[dict[str, Any]] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> TopicLog:
        self._consumer.subscribe([self.topic])
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(5)
        self._consumer.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self._consumer.poll(0.1)
            if msg is None or msg.error():
                continue
            raw = msg.value()
            value = raw if self._deserializer is None else self._decode(self._deserializer, raw)
            entry = {
                "key": msg.key(),
                "value": value,
                "headers": dict(msg.headers() or []),
                "timestamp": msg.timestamp()[1],
            }
            with self._lock:
                self.records.append(entry)

    def _decode(self, deserializer: AvroDeserializer, raw: bytes | None) -> Any:
        context = SerializationContext(self.topic, MessageField.VALUE)
        return on_a_live_connection(lambda: deserializer(raw, context))

    def values(self) -> list[Any]:
        with self._lock:
            return [r["value"] for r in self.records]

    def statuses(
        self, command_id: str | None = None, robot: str | None = None, site: str | None = None
    ) -> list[str]:
        """The statuses in Kafka order; ``site=""`` keeps the ones the uplink decided itself."""
        return [
            v["status"]
            for v in self.values()
            if command_id in (None, v["command_id"])
            and robot in (None, v["robot"])
            and site in (None, v["site"])
        ]


# -- fleetlink processes ---------------------------------------------------------------------


@cache
def command_keys() -> tuple[Path, Path]:
    """One command signing key pair for the test process: (the uplink's private, the repeaters' public)."""
    directory = Path(tempfile.mkdtemp(prefix="fleetlink-command-keys-"))
    atexit.register(shutil.rmtree, directory, True)
    return write_command_key(directory)


def uplink_config(
    bootstrap: str, registry_url: str, cloud: str, commands: list[dict[str, Any]], *, suffix: str
) -> UplinkConfig:
    return UplinkConfig.model_validate(
        {
            "kafka": {"bootstrap_servers": bootstrap, "client_id": f"uplink-{suffix}", "linger": "0ms"},
            "registry": {"url": registry_url},
            "zenoh": {"mode": "client", "connect": [cloud]},
            "topics": {
                "dead_letter": f"dlq.{suffix}",
                "registrations": f"robots.{suffix}",
                "command_dead_letter": f"cmd-dlq.{suffix}",
                "command_status": f"cmd-status.{suffix}",
                "refused": f"refused.{suffix}",
            },
            "commands": commands,
            "command_signing": {"key_file": str(command_keys()[0])},
        }
    )


def lightring_mapping(topic: str, *, period: str = "1s", lease: str = "10s", **extra: Any) -> dict[str, Any]:
    return {
        "name": "lightring",
        "from": topic,
        "to": "/{key}/cmd_lightring",
        "type": LIGHTRING,
        "repeat": {"period": period, "lease": lease},
    } | extra


@dataclass
class LightringBed:
    """One site on a WAN, an uplink config with one light-ring command mapping, its topic made."""

    ts: Typestore
    run: str
    topic: str
    producer: CommandProducer
    leds: LedLog
    site: Site
    config: UplinkConfig


@contextmanager
def lightring_bed(
    bootstrap: str, registry_url: str, *, period: str = "1s", lease: str = "10s"
) -> Iterator[LightringBed]:
    ts, run = irobot_store(), uid()
    topic = f"cmd.lightring.{run}"
    producer = CommandProducer(bootstrap, registry_url, ts)
    with Wan() as wan:
        site = wan.add_site("site-a")
        config = uplink_config(
            bootstrap,
            registry_url,
            wan.cloud.endpoint,
            [lightring_mapping(topic, period=period, lease=lease)],
            suffix=run,
        )
        create_topics(bootstrap, topic)
        yield LightringBed(ts, run, topic, producer, LedLog(), site, config)


def repeater_config(site: Site, state_dir: Path, **repeater: Any) -> RepeaterConfig:
    return RepeaterConfig.model_validate(
        {
            "repeater": {
                "site": site.name,
                "state_dir": str(state_dir),
                "id": f"rep-{site.name}",
                "heartbeat": "300ms",
                "status_timeout": "1s",
                "command_keys": [str(command_keys()[1])],
                **repeater,
            },
            "ros": {"distro": "jazzy", "message_paths": [str(IROBOT)]},
            "zenoh": {"mode": "client", "connect": [site.endpoint]},
        }
    )


@contextmanager
def running_uplink(config: UplinkConfig) -> Iterator[Uplink]:
    with Uplink(config) as uplink:
        router = uplink.commands
        assert router is not None
        wait_until(router.assigned.is_set, timeout=30, message="command partitions assigned")
        yield uplink


@dataclass
class LedLog:
    """What each simulated robot's light ring received: (receive time, colour name)."""

    seen: dict[str, list[tuple[float, str]]] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def __call__(self, robot: str, state: LedState) -> None:
        with self.lock:
            self.seen.setdefault(robot, []).append((state.at, state.name))

    def of(self, robot: str) -> list[tuple[float, str]]:
        with self.lock:
            return list(self.seen.get(robot, []))

    def count(self, robot: str, colour: str | None = None) -> int:
        return sum(1 for _t, name in self.of(robot) if colour is None or name == colour)

    def first(self, robot: str, colour: str) -> float | None:
        return next((t for t, name in self.of(robot) if name == colour), None)

    def last(self, robot: str, colour: str | None = None) -> float | None:
        times = [t for t, name in self.of(robot) if colour is None or name == colour]
        return max(times) if times else None


def fleet(site: Site, typestore: Typestore, leds: LedLog, *, robots: int = 0, prefix: str = "tb4_") -> Fleet:
    """Simulated robots at ``site`` (sensors at 1 Hz, light ring subscriber); add more with add_robot."""
    return Fleet(robot_config(site.endpoint), typestore, robots=robots, prefix=prefix, rate=1.0, on_led=leds)


def wait_repeater_sees(repeater: Repeater, topic: str, timeout: float = 10.0) -> None:
    wait_until(lambda: repeater.subscribers(topic) > 0, timeout=timeout, message=f"subscriber on {topic}")
