"""Commands, Kafka -> robots: latency and WAN bytes per command, fleetlink vs repeats from the cloud.

    .venv/bin/python bench/bench_commands.py [--robots 50] [--rounds 5] [--period 1] [--lease 10]

One site with ``--robots`` simulated robots (rmw_zenoh nodes /tb4_NN/create3 on one session,
each subscribing to ``/tb4_NN/cmd_lightring``) and a repeater, behind a site Zenoh router that
reaches the cloud router only through a TcpRelay, which counts every byte of the WAN link both
ways. In the cloud: the uplink with one command mapping (LightringLeds, ``--period``,
``--lease``). Kafka and the registry come from $KAFKA_BOOTSTRAP / $SCHEMA_REGISTRY_URL, or a
LocalStack started here. Commands are produced with the stock AvroSerializer, key = robot.

1. **idle**: WAN bytes per second with nothing to do (router keep-alives, the repeater's
   heartbeats): the baseline subtracted below.
2. **latency**: ``--rounds`` rounds of one command per robot (each round supersedes the last),
   after a warm-up round; latency = Kafka produce call -> the CDR sample in the robot's
   subscriber callback (same host, same clock).
3. **fleetlink WAN**: one command per robot, and the WAN bytes from the first produce until every
   lease has ended and every status record is acknowledged (envelopes, replies, statuses).
4. **cloud repeats**: the naive alternative in the same run: a cloud-side rmw_zenoh publisher per
   robot sends the command every period for the lease itself, so every repeat crosses the WAN.

The routers are plain router-mode sessions (no ACL), so the naive mode's ROS traffic may cross.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import yaml
import zenoh
from confluent_kafka import Consumer, ConsumerGroupState, KafkaException, Producer, TopicPartition
from confluent_kafka.admin import AdminClient, NewTopic
from confluent_kafka.schema_registry import SchemaRegistryClient
from confluent_kafka.schema_registry.avro import AvroSerializer
from confluent_kafka.serialization import MessageField, SerializationContext

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fleetlink.common.command_keys import write_command_key  # noqa: E402
from fleetlink.localstack.process import exit_on_sigterm  # noqa: E402
from fleetlink.localstack.relay import TcpRelay  # noqa: E402
from fleetlink.localstack.stack import LocalStack  # noqa: E402
from fleetlink.localstack.zenoh_router import ZenohRouter  # noqa: E402
from fleetlink.repeater.config import RepeaterConfig  # noqa: E402
from fleetlink.repeater.service import Repeater  # noqa: E402
from fleetlink.roswire.node import RosNode  # noqa: E402
from fleetlink.roswire.subscriber import RosSample  # noqa: E402
from fleetlink.schemas.avro_schema import avro_schema  # noqa: E402
from fleetlink.schemas.codec import get_codec  # noqa: E402
from fleetlink.schemas.typestore import load_typestore  # noqa: E402
from fleetlink.uplink.config import UplinkConfig  # noqa: E402
from fleetlink.uplink.service import Uplink  # noqa: E402
from tests.paths import IROBOT  # noqa: E402

LIGHTRING = "irobot_create_msgs/msg/LightringLeds"
NO_GOSSIP = {"scouting/gossip/enabled": False}
REGISTRATION = {  # what the edge agents write to the registrations topic (the fields the uplink reads)
    "type": "record",
    "name": "RobotRegistration",
    "namespace": "fleetlink",
    "fields": [
        {"name": "robot", "type": "string"},
        {"name": "site", "type": "string"},
        {"name": "event", "type": "string"},
    ],
}


def client(endpoint: str) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


def wait_for(pred: Callable[[], bool], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > deadline:
            raise SystemExit(f"bench: timed out waiting for {what}")
        time.sleep(0.01)


def pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))]


@contextmanager
def kafka_stack() -> Iterator[tuple[str, str]]:
    env_bootstrap, env_registry = os.environ.get("KAFKA_BOOTSTRAP"), os.environ.get("SCHEMA_REGISTRY_URL")
    if env_bootstrap and env_registry:
        yield env_bootstrap, env_registry
        return
    with tempfile.TemporaryDirectory(prefix="bench-commands-") as tmp:
        stack = LocalStack(Path(tmp))
        info = stack.start()
        try:
            yield info.bootstrap, info.registry_url
        finally:
            stack.stop()


class Robots:
    """``n`` rmw_zenoh nodes on one session at the site; records (robot, payload, receive time)."""

    def __init__(self, endpoint: str, n: int, typestore: Any) -> None:
        self.names = [f"tb4_{i:02d}" for i in range(1, n + 1)]
        self._session = zenoh.open(client(endpoint))
        self._nodes = [
            RosNode("create3", f"/{name}", session=self._session, typestore=typestore).start()
            for name in self.names
        ]
        self.received: list[tuple[str, bytes, float]] = []
        self._lock = threading.Lock()
        for name, node in zip(self.names, self._nodes, strict=True):
            node.create_subscriber("cmd_lightring", LIGHTRING, self._callback(name))

    def _callback(self, name: str) -> Callable[[RosSample], None]:
        def on_sample(sample: RosSample) -> None:
            now = time.time()
            with self._lock:
                self.received.append((name, sample.payload, now))

        return on_sample

    def first(self, payload: bytes) -> dict[str, float]:
        with self._lock:
            out: dict[str, float] = {}
            for name, data, at in self.received:
                if data == payload and name not in out:
                    out[name] = at
            return out

    def count(self) -> int:
        with self._lock:
            return len(self.received)

    def close(self) -> None:
        for node in self._nodes:
            node.stop()
        self._session.close()


@contextmanager
def uplink_process(config: UplinkConfig, path: Path) -> Iterator[subprocess.Popen[bytes]]:
    """``fleetlink uplink run`` in its own process (the cloud side), stopped with SIGTERM."""
    path.write_text(yaml.safe_dump(config.model_dump(mode="json", by_alias=True, exclude_none=True)))
    with path.with_suffix(".log").open("wb") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "fleetlink.cli", "uplink", "run", "-c", str(path)],
            cwd=ROOT,
            stdout=log,
            stderr=subprocess.STDOUT,
        )
    try:
        yield proc
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)


def main(argv: list[str] | None = None) -> int:
    exit_on_sigterm()  # stopped with SIGTERM: the stack and the processes started here stop too
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--robots", type=int, default=50)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--period", type=float, default=1.0)
    parser.add_argument("--lease", type=float, default=10.0)
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    parser.add_argument(
        "--uplink-in-process",
        action="store_true",
        help="run the uplink in this process (default: its own process, as deployed)",
    )
    args = parser.parse_args(argv)
    ts = load_typestore("jazzy", [IROBOT])
    codec = get_codec(ts, LIGHTRING, "jazzy")
    schema = avro_schema(ts, LIGHTRING, "jazzy")
    run = uuid.uuid4().hex[:8]
    topic = f"bench.commands.{run}"
    results: dict[str, Any] = {"robots": args.robots, "period_s": args.period, "lease_s": args.lease}

    def datum(red: int) -> dict[str, Any]:
        return {
            "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
            "leds": [{"red": red, "green": 0, "blue": 0}] * 6,
            "override_system": True,
        }

    def cdr(red: int) -> bytes:
        return codec.avro_to_cdr(codec.encode_datum(datum(red)))

    with (
        kafka_stack() as (bootstrap, registry_url),
        ExitStack() as stack,
        tempfile.TemporaryDirectory(prefix="bench-repeater-") as state,
    ):
        admin = AdminClient({"bootstrap.servers": bootstrap})
        admin.create_topics([NewTopic(topic, num_partitions=1, replication_factor=1)])[topic].result(20)
        serializer = AvroSerializer(
            SchemaRegistryClient({"url": registry_url}), json.dumps(schema), to_dict=lambda obj, _ctx: obj
        )
        producer = Producer({"bootstrap.servers": bootstrap, "linger.ms": 0})
        registrations = f"bench.robots.{run}"
        register = AvroSerializer(
            SchemaRegistryClient({"url": registry_url}),
            json.dumps(REGISTRATION),
            to_dict=lambda obj, _ctx: obj,
        )
        for i in range(1, args.robots + 1):
            robot = f"tb4_{i:02d}"
            producer.produce(
                registrations,
                key=robot.encode(),
                value=register(
                    {"robot": robot, "site": "site-a", "event": "registered"},
                    SerializationContext(registrations, MessageField.VALUE),
                ),
            )
        producer.flush(10)

        cloud = stack.enter_context(ZenohRouter(extra=NO_GOSSIP))
        relay = stack.enter_context(TcpRelay(cloud.port))
        site = stack.enter_context(ZenohRouter(connect=(relay.endpoint,), extra=NO_GOSSIP))
        robots = Robots(site.endpoint, args.robots, ts)
        stack.callback(robots.close)
        signing_key, public_key = write_command_key(
            Path(state) / "keys"
        )  # the uplink signs, the repeater checks
        repeater = stack.enter_context(
            Repeater(
                RepeaterConfig.model_validate(
                    {
                        "repeater": {
                            "site": "site-a",
                            "state_dir": state,
                            "id": "bench",
                            "heartbeat": "2s",
                            "command_keys": [str(public_key)],
                        },
                        "ros": {"distro": "jazzy", "message_paths": [str(IROBOT)]},
                        "zenoh": {"mode": "client", "connect": [site.endpoint]},
                    }
                )
            )
        )
        config = UplinkConfig.model_validate(
            {
                "kafka": {"bootstrap_servers": bootstrap, "client_id": f"bench-{run}", "linger": "0ms"},
                "registry": {"url": registry_url},
                "zenoh": {"mode": "client", "connect": [cloud.endpoint]},
                "topics": {
                    "registrations": registrations,
                    "command_status": f"bench.status.{run}",
                    "command_dead_letter": f"bench.dlq.{run}",
                    "dead_letter": f"bench.dl.{run}",
                },
                "command_signing": {"key_file": str(signing_key)},
                "commands": [
                    {
                        "name": "lightring",
                        "from": topic,
                        "to": "/{key}/cmd_lightring",
                        "type": LIGHTRING,
                        "repeat": {"period": f"{args.period}s", "lease": f"{args.lease}s"},
                    }
                ],
            }
        )
        produced = [0]
        if args.uplink_in_process:
            uplink = stack.enter_context(Uplink(config))
            router = uplink.commands
            assert router is not None
            wait_for(router.assigned.is_set, 60, "command partitions")
            in_flight: Callable[[], int] = router.in_flight
        else:
            stack.enter_context(uplink_process(config, Path(state) / "uplink.yaml"))
            lag = Consumer(
                {
                    "bootstrap.servers": bootstrap,
                    "group.id": f"{config.kafka.client_id}.commands",
                    "enable.auto.commit": False,
                }
            )
            stack.callback(lag.close)

            def group_ready() -> bool:
                group = f"{config.kafka.client_id}.commands"
                try:
                    described = admin.describe_consumer_groups([group])[group].result(10)
                except KafkaException:
                    return False
                return bool(described.state == ConsumerGroupState.STABLE and described.members)

            wait_for(group_ready, 120, "the uplink process to join its consumer group")

            def in_flight() -> int:
                if produced[0] == 0:
                    return 0
                done: int = lag.committed([TopicPartition(topic, 0)], timeout=10)[0].offset
                return produced[0] - max(done, 0)

        wait_for(
            lambda: all(repeater.subscribers(f"/{n}/cmd_lightring") for n in robots.names),
            30,
            "the repeater to see every robot",
        )

        def send(robot: str, red: int) -> float:
            value = serializer(datum(red), SerializationContext(topic, MessageField.VALUE))
            sent = time.time()
            producer.produce(
                topic,
                key=robot.encode(),
                value=value,
                headers=[("fleetlink-command-id", f"{robot}-{red}-{run}".encode())],
            )
            producer.poll(0)
            produced[0] += 1
            return sent

        def settled() -> bool:
            return not repeater.schedule.active() and repeater.pending_statuses() == 0 and in_flight() == 0

        def phase(spent: int, window: float, samples: int) -> dict[str, Any]:
            per_command = (spent - idle_rate * window) / len(robots.names)
            return {
                "wan_bytes": spent,
                "window_s": round(window, 1),
                "wan_bytes_per_command": round(per_command),
                "samples_at_robots": samples,
            }

        def round_of_commands(red: int, timeout: float) -> list[float]:
            sent = {name: send(name, red) for name in robots.names}
            producer.flush(10)
            expected = cdr(red)
            wait_for(lambda: len(robots.first(expected)) == len(robots.names), timeout, f"commands {red}")
            got = robots.first(expected)
            return [got[name] - sent[name] for name in robots.names]

        # warm-up: the uplink is up, has read the registrations, the first envelopes went out
        round_of_commands(9, 120)
        wait_for(settled, args.lease + 30, "the warm-up commands to end")

        # 1. idle baseline
        idle_s = max(5.0, args.lease)
        before, start = relay.counters.total_bytes, time.monotonic()
        time.sleep(idle_s)
        idle_rate = (relay.counters.total_bytes - before) / (time.monotonic() - start)
        results["idle_bytes_per_s"] = round(idle_rate, 1)

        # 2. latency: rounds of one command per robot (each supersedes the one before)
        latencies: list[float] = []
        for rnd in range(args.rounds):
            latencies += round_of_commands(10 + rnd, 30)
        results["latency_ms"] = {
            "p50": round(pct(latencies, 0.50) * 1000, 1),
            "p99": round(pct(latencies, 0.99) * 1000, 1),
            "max": round(max(latencies) * 1000, 1),
            "mean": round(statistics.fmean(latencies) * 1000, 1),
            "samples": len(latencies),
        }
        wait_for(settled, args.lease + 30, "the latency rounds to end")

        # 3. fleetlink: one command per robot, WAN bytes for its whole life
        before, start = relay.counters.total_bytes, time.monotonic()
        received_before = robots.count()
        for name in robots.names:
            send(name, 200)
        producer.flush(10)
        wait_for(lambda: len(robots.first(cdr(200))) == len(robots.names), 30, "fleetlink commands")
        wait_for(lambda: in_flight() == 0, 30, "every forward acknowledged")
        forwarded = relay.counters.total_bytes - before
        wait_for(settled, args.lease + 30, "fleetlink commands to end")
        spent = relay.counters.total_bytes - before
        window = time.monotonic() - start
        results["fleetlink"] = phase(spent, window, robots.count() - received_before)
        results["fleetlink"]["forward_bytes_per_command"] = round(forwarded / len(robots.names))

        # 4. naive: every repeat from the cloud
        with zenoh.open(client(cloud.endpoint)) as cloud_session:
            node = RosNode("cloud_commands", "/", session=cloud_session, typestore=ts).start()
            payload = cdr(201)
            publishers = [node.create_publisher(f"/{name}/cmd_lightring", LIGHTRING) for name in robots.names]
            time.sleep(1.0)  # declarations settle: measured below is the commands' own traffic
            before, start = relay.counters.total_bytes, time.monotonic()
            received_before = robots.count()
            repeats = max(1, round(args.lease / args.period))
            for _ in range(repeats):
                tick = time.monotonic()
                for pub in publishers:
                    pub.publish_cdr(payload)
                time.sleep(max(0.0, args.period - (time.monotonic() - tick)))
            wait_for(
                lambda: robots.count() - received_before >= len(robots.names) * repeats, 10, "naive samples"
            )
            spent = relay.counters.total_bytes - before
            window = time.monotonic() - start
            for pub in publishers:
                pub.stop()
            node.stop()
        results["cloud_repeats"] = phase(spent, window, robots.count() - received_before)

    if args.json:
        print(json.dumps(results, indent=2))
    else:
        lat, fl, naive = results["latency_ms"], results["fleetlink"], results["cloud_repeats"]
        print(f"robots {args.robots}, period {args.period} s, lease {args.lease} s")
        print(
            f"latency Kafka produce -> ROS sample: p50 {lat['p50']} ms, p99 {lat['p99']} ms, "
            f"max {lat['max']} ms ({lat['samples']} commands)"
        )
        print(f"idle WAN: {results['idle_bytes_per_s']} B/s")
        for label, figures in (("fleetlink:    ", fl), ("cloud repeats:", naive)):
            print(
                f"{label} {figures['wan_bytes_per_command']:>7} WAN bytes per command "
                f"({figures['wan_bytes']} B in {figures['window_s']} s; "
                f"{figures['samples_at_robots']} samples at the robots)"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
