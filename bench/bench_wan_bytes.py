"""WAN bytes per robot-hour for the real Husky bag: raw forwarding, router downsampling, fleetlink.

    .venv/bin/python bench/bench_wan_bytes.py [--slice 150] [--speed 1] [--modes raw,ds1,...]

One robot replays robot_localization_husky (/imu/data 30 Hz, /husky_velocity_controller/odom
10 Hz, /fix 2.5 Hz; 395 s) into a site Zenoh router. The site router reaches the cloud router
only through a TcpRelay (fleetlink.localstack.relay) that counts every byte of that WAN link,
both ways. Every mode has its own robot, routers and relay, and all modes run at the same time
(so a real-time replay of all of them takes the time of one):

- raw:         no fleetlink; a cloud-side subscriber on ``0/husky_1/**`` pulls every sample;
- ds1:         the same, the site router thinning raw keys on egress to 1 Hz per topic;
- ds5:         the same at the rates of deploy/zenoh/edge-router.json5 (imu 5, odom 5, fix 1 Hz);
- fl-raw:      the edge agent maps the three topics unchanged to Kafka through the uplink
               (at-least-once spool, zstd batches, acknowledgements), default WAN settings;
- fl-agg:      the edge agent aggregates each topic per robot into 1 s windows; default settings
               (an aggregate mapping's records may wait one window, 1 s, to share a batch);
- fl-agg-20ms: fl-agg with the mappings' ``linger: 20ms`` (the edge's default for other mappings);
- fl-agg-10s:  fl-agg with the mappings' ``linger: 10s`` (batches wait up to 10 s: more latency).

Each message carries its recorded time as its rmw_zenoh source timestamp (the aggregate windows
follow source time). ``--speed`` replays faster and scales the wall-clock settings (downsampling
frequencies times speed, linger divided by speed), but the edge's batching still sees different timing; the
figures in docs/wan_bytes.md are real time. Kafka and the schema registry come from
$KAFKA_BOOTSTRAP / $SCHEMA_REGISTRY_URL, or a LocalStack started here.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import threading
import time
import uuid
from collections import Counter
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh
from confluent_kafka import Consumer, TopicPartition
from rosbags.rosbag2 import Reader

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fleetlink.edge.agent import EdgeAgent  # noqa: E402
from fleetlink.edge.config import EdgeConfig  # noqa: E402
from fleetlink.edge.runtime.registration import EVENT_FINGERPRINT  # noqa: E402
from fleetlink.localstack.process import exit_on_sigterm  # noqa: E402
from fleetlink.localstack.relay import TcpRelay  # noqa: E402
from fleetlink.localstack.stack import LocalStack  # noqa: E402
from fleetlink.localstack.zenoh_router import ZenohRouter  # noqa: E402
from fleetlink.roswire.node import RosNode  # noqa: E402
from fleetlink.roswire.publisher import RosPublisher  # noqa: E402
from fleetlink.schemas.typestore import load_typestore  # noqa: E402
from fleetlink.uplink.config import UplinkConfig  # noqa: E402
from fleetlink.uplink.service import Uplink  # noqa: E402
from fleetlink.wire import encode_batch_payloads  # noqa: E402
from tests.paths import HUSKY  # noqa: E402

BAG = HUSKY
ROBOT = "husky_1"
IMU, ODOM, FIX = "/imu/data", "/husky_velocity_controller/odom", "/fix"
TYPES = {IMU: "sensor_msgs/msg/Imu", ODOM: "nav_msgs/msg/Odometry", FIX: "sensor_msgs/msg/NavSatFix"}
SHORT = {IMU: "imu", ODOM: "odom", FIX: "fix"}
AGGREGATES: dict[str, dict[str, Any]] = {
    IMU: {
        "fields": [
            "linear_acceleration.x",
            "linear_acceleration.y",
            "linear_acceleration.z",
            "angular_velocity.z",
        ],
        "ops": ["mean", "min", "max", "stddev"],
    },
    ODOM: {"fields": ["twist.twist.linear.x", "twist.twist.angular.z"], "ops": ["mean", "max"]},
    FIX: {"fields": ["latitude", "longitude"], "ops": ["last"]},
}
RULE_KEYS = {"imu": "*/**/imu/**", "odom": "*/**/odom/**", "fix": "*/**/fix/**"}
RATES_HZ: dict[str, dict[str, float]] = {
    "ds1": dict.fromkeys(RULE_KEYS, 1.0),
    "ds5": {"imu": 5.0, "odom": 5.0, "fix": 1.0},
}  # edge-router.json5
LINGER_S = 0.02  # edge.config.WanSection's default
MAPPING_LINGER_S = {"fl-raw": None, "fl-agg": 1.0, "fl-agg-20ms": 0.02, "fl-agg-10s": 10.0}
"""A mapping's linger (None: the edge's wan.linger; 1 s: what an aggregate mapping gets by default)."""
MODES = ("raw", "ds1", "ds5", "fl-raw", "fl-agg", "fl-agg-20ms", "fl-agg-10s")
MARKER = "/bench_end"
NS = 1_000_000_000
Message = tuple[int, str, bytes]  # (recorded ns, bag topic, CDR)


@dataclass(frozen=True)
class Result:
    mode: str
    up: int  # site -> cloud bytes from the first message to the last sample/ack
    down: int  # cloud -> site bytes, same span
    crossed: int  # samples (raw modes) or Kafka records (fleetlink modes) that reached the cloud
    published: int
    bag_s: float
    setup_bytes: int  # handshakes and declarations before the replay
    idle_bps: float  # WAN bytes/s with everything up and no robot traffic
    detail: str

    @property
    def total(self) -> int:
        return self.up + self.down

    @property
    def per_hour(self) -> float:
        return self.total * 3600 / self.bag_s


def load_bag(slice_s: float) -> list[Message]:
    with Reader(BAG) as reader:
        conns = [c for c in reader.connections if c.topic in TYPES]
        out = [(ts, c.topic, bytes(raw)) for c, ts, raw in reader.messages(connections=conns)]
    return [m for m in out if m[0] < out[0][0] + int(slice_s * NS)] if slice_s > 0 else out


def bag_seconds(messages: Sequence[Message]) -> float:
    """The span of robot time replayed: first to last message."""
    return (messages[-1][0] - messages[0][0]) / NS


def topic_of(key: str) -> str:
    """The bag topic of a raw key ``0/husky_1/<topic>/<type>/<hash>`` (or the end marker)."""
    for topic in (*TYPES, MARKER):
        if key.startswith(f"0/{ROBOT}{topic}/") or key == f"0/{ROBOT}{topic}":
            return topic
    return key


def client_config(endpoint: str) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


def wait_for(pred: Callable[[], object], timeout: float, what: str) -> None:
    pause = threading.Event()  # never set: wait() is the polling timer
    deadline = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > deadline:
            raise RuntimeError(f"timed out after {timeout:g} s waiting for {what}")
        pause.wait(0.05)


class Wan:
    """cloud router <- relay <- site router: the only path between the site and the cloud."""

    def __init__(self, stack: ExitStack, site_extra: dict[str, Any]) -> None:
        # Nothing on the site may find the cloud router directly (no gossip), and the routers must
        # not pass payloads over shared memory: zenoh moves messages above ~3 KB between processes
        # on one host that way, past the relay, which a real WAN link cannot do.
        wan_only = {"scouting/gossip/enabled": False, "transport/shared_memory/enabled": False}
        self.cloud = stack.enter_context(ZenohRouter(extra=wan_only))
        self.relay = stack.enter_context(TcpRelay(self.cloud.port))
        self.site = stack.enter_context(
            ZenohRouter(connect=(self.relay.endpoint,), extra={**wan_only, **site_extra})
        )
        wait_for(lambda: self.relay.counters.connections >= 1 and self.bytes() > 0, 10, "the WAN link")

    def bytes(self) -> int:
        return self.relay.counters.total_bytes

    def split(self) -> tuple[int, int]:
        c = self.relay.counters
        return c.upstream_bytes, c.downstream_bytes

    def settle_and_idle(self, idle_s: float) -> float:
        """Wait (≤ 10 s) for set-up traffic to stop for 1 s, then the idle rate over ``idle_s``."""
        pause, deadline = threading.Event(), time.monotonic() + 10
        last, quiet_since = self.bytes(), time.monotonic()
        while time.monotonic() - quiet_since < 1.0 and time.monotonic() < deadline:
            pause.wait(0.1)
            if self.bytes() != last:
                last, quiet_since = self.bytes(), time.monotonic()
        before, began = self.bytes(), time.monotonic()
        pause.wait(idle_s)
        return (self.bytes() - before) / (time.monotonic() - began)


def robot(stack: ExitStack, endpoint: str) -> dict[str, RosPublisher]:
    node = stack.enter_context(
        RosNode("replay", f"/{ROBOT}", config=client_config(endpoint), typestore=load_typestore("jazzy"))
    )
    return {t: node.create_publisher(f"/{ROBOT}{t}", kind, congestion="block") for t, kind in TYPES.items()}


def replay(pubs: dict[str, RosPublisher], messages: Sequence[Message], speed: float) -> float:
    """Publish at ``speed`` times the recorded pace, each message with its recorded time as source
    timestamp; returns how late against the schedule the worst message went out (s)."""
    pace = threading.Event()
    first, start, late = messages[0][0], time.monotonic(), 0.0
    for ts, topic, raw in messages:
        wait = start + (ts - first) / NS / speed - time.monotonic()
        if wait > 0:
            pace.wait(wait)
        else:
            late = max(late, -wait)
        pubs[topic].publish_cdr(raw, source_ts_ns=ts)
    return late


def downsampling(rates_hz: dict[str, float], speed: float) -> dict[str, Any]:
    """Egress rules on every link of the site router. Robots only publish, so raw keys leave the
    site router on the WAN link only (plain TCP here, so there is no TLS link to select)."""
    return {
        "downsampling": [
            {
                "id": "wan-raw-egress",
                "flows": ["egress"],
                "messages": ["put", "delete"],
                "rules": [{"key_expr": RULE_KEYS[k], "freq": hz * speed} for k, hz in rates_hz.items()],
            }
        ]
    }


def run_raw(mode: str, messages: Sequence[Message], speed: float, idle_s: float) -> Result:
    rates = RATES_HZ.get(mode)
    with ExitStack() as stack:
        wan = Wan(stack, downsampling(rates, speed) if rates else {})
        got: Counter[str] = Counter()
        lock = threading.Lock()

        def on_sample(sample: zenoh.Sample) -> None:
            with lock:
                got[topic_of(str(sample.key_expr))] += 1

        cloud = stack.enter_context(zenoh.open(client_config(wan.cloud.endpoint)))
        stack.callback(cloud.declare_subscriber(f"0/{ROBOT}/**", on_sample).undeclare)
        pubs = robot(stack, wan.site.endpoint)
        wait_for(lambda: all(p.has_subscribers() for p in pubs.values()), 15, "the cloud subscriber")
        idle = wan.settle_and_idle(idle_s)
        setup, (up0, down0) = wan.bytes(), wan.split()
        late = replay(pubs, messages, speed)
        # a marker on an unthinned key, behind the data on the same link: once it is in, every
        # sample the site router let through is in too (its ~100 bytes are counted)
        next(iter(pubs.values())).node.session.put(f"0/{ROBOT}{MARKER}", b"")
        wait_for(lambda: got[MARKER] == 1, 30, "the end marker at the cloud")
        up, down = wan.split()
    crossed = sum(got.values()) - 1
    if rates is None and crossed != len(messages):
        raise RuntimeError(f"{mode}: {crossed} of {len(messages)} raw samples crossed")
    per_topic = ", ".join(f"{SHORT[t]} {got[t]}" for t in TYPES)
    rules = "" if rates is None else "rules " + "/".join(f"{hz:g}" for hz in rates.values()) + " Hz; "
    return Result(
        mode,
        up - up0,
        down - down0,
        crossed,
        len(messages),
        bag_seconds(messages),
        setup,
        idle,
        f"{rules}{per_topic}; {(up - up0) / max(crossed, 1):.0f} B up per sample; "
        f"replay late by {late * 1000:.0f} ms at worst",
    )


def windows(messages: Sequence[Message]) -> int:
    """How many non-empty 1 s tumbling windows (aligned on the epoch) the topics fill, summed."""
    return len({(topic, ts // NS) for ts, topic, _ in messages})


def kafka_records(bootstrap: str, topics: Sequence[str]) -> int:
    consumer = Consumer({"bootstrap.servers": bootstrap, "group.id": f"bench-{uuid.uuid4().hex}"})
    try:
        return sum(consumer.get_watermark_offsets(TopicPartition(t, 0), timeout=10)[1] for t in topics)
    finally:
        consumer.close()


def schema_bytes(spool: Path, *, aggregate: bool) -> str:
    """What each schema the mode's batches carry adds to a batch: JSON size -> zstd batch growth."""

    def batch(schemas: dict[bytes, str]) -> int:
        return len(
            encode_batch_payloads(
                site="s", edge_id="e", stream="durable", items=[(1, b"")], schemas=schemas, codec="zstd"
            )
        )

    sizes = []
    for path in sorted((spool / "schemas").glob("*.json")):
        fp, text = bytes.fromhex(path.stem), path.read_text(encoding="utf-8")
        if fp != EVENT_FINGERPRINT and ('"fleetlink.agg' in text) == aggregate:
            sizes.append(f"{len(text.encode())}->{batch({fp: text}) - batch({})}")
    return ", ".join(sizes)


def run_fleetlink(
    mode: str,
    messages: Sequence[Message],
    speed: float,
    idle_s: float,
    *,
    bootstrap: str,
    registry: str,
    work: Path,
) -> Result:
    run, aggregate = uuid.uuid4().hex[:8], mode.startswith("fl-agg")
    linger = MAPPING_LINGER_S[mode]
    topics = {t: f"bench.wan.{run}.{SHORT[t]}{'_1s' if aggregate else ''}" for t in TYPES}
    mappings: list[dict[str, Any]] = []
    for t, kind in TYPES.items():
        mapping: dict[str, Any] = {"name": SHORT[t], "from": f"/{{robot}}{t}", "to": topics[t], "type": kind}
        if aggregate:
            mapping["stages"] = [{"type": "aggregate", "window": "1s", **AGGREGATES[t]}]
        if linger is not None and (mode != "fl-agg" or speed != 1):  # fl-agg: the default, unless scaled
            mapping["linger"] = us(linger / speed)
        mappings.append(mapping)
    side_topics = {"dead_letter": f"bench.wan.{run}.dead-letter", "registrations": f"bench.wan.{run}.robots"}
    spool = work / run
    with ExitStack() as stack:
        wan = Wan(stack, {})
        stack.enter_context(
            Uplink(
                UplinkConfig.model_validate(
                    {
                        "kafka": {"bootstrap_servers": bootstrap},
                        "registry": {"url": registry},
                        "zenoh": {"mode": "client", "connect": [wan.cloud.endpoint]},
                        "topics": side_topics,
                    }
                )
            )
        )
        agent = stack.enter_context(
            EdgeAgent(
                EdgeConfig.model_validate(
                    {
                        "site": f"bench-{run}",
                        "edge_id": "edge-1",
                        "zenoh": {"mode": "client", "connect": [wan.site.endpoint]},
                        "robot_types": {"husky": {"match": "/husky_*", "mappings": mappings}},
                        "spool": {"dir": str(spool)},
                        "wan": {"linger": us(LINGER_S / speed)},
                        "topics": side_topics,
                    }
                )
            )
        )

        def durable() -> dict[str, Any]:
            stream: dict[str, Any] = agent.snapshot()["streams"]["durable"]
            return stream

        pubs = robot(stack, wan.site.endpoint)
        wait_for(lambda: all(p.has_subscribers() for p in pubs.values()), 15, "the edge's subscriptions")
        # the robot's registration event is the first record: the path to Kafka is up once it is acked
        wait_for(
            lambda: durable()["buffer"]["appended"] >= 1 and durable()["buffer"]["depth"] == 0,
            30,
            "the registration event acknowledged",
        )
        idle = wan.settle_and_idle(idle_s)
        setup, (up0, down0), base = wan.bytes(), wan.split(), durable()
        late = replay(pubs, messages, speed)
        expected = windows(messages) if aggregate else len(messages)

        def delivered() -> bool:
            buffer = durable()["buffer"]
            return bool(buffer["appended"] - base["buffer"]["appended"] >= expected and buffer["depth"] == 0)

        wait_for(
            delivered, 60 + (linger or LINGER_S) / speed, f"{mode}: {expected} records spooled and acked"
        )
        up, down = wan.split()
        end = durable()
        crossed = kafka_records(bootstrap, list(topics.values()))
        schemas = schema_bytes(spool, aggregate=aggregate)
    batches = end["sender"]["batches_acked"] - base["sender"]["batches_acked"]
    payload = end["sender"]["bytes_sent"] - base["sender"]["bytes_sent"]
    if crossed != expected:
        raise RuntimeError(f"{mode}: {crossed} records in Kafka, {expected} expected")
    n = max(batches, 1)
    return Result(
        mode,
        up - up0,
        down - down0,
        crossed,
        len(messages),
        bag_seconds(messages),
        setup,
        idle,
        f"{batches} batches of {crossed / n:.1f} records; per batch: {payload / n:.0f} B batch "
        f"payload, {(up - up0) / n:.0f} B up, {(down - down0) / n:.0f} B down (ack); "
        f"schemas JSON->zstd B: {schemas}; "
        f"replay late by {late * 1000:.0f} ms at worst",
    )


def us(seconds: float) -> str:
    return f"{seconds * 1e6:.0f}us"


def table(results: Sequence[Result]) -> str:
    raw = next((r for r in results if r.mode == "raw"), None)
    rows = [
        "| mode | WAN bytes (up + down) | MB per robot-hour | crossing the WAN | raw / mode |",
        "|---|---|---|---|---|",
    ]
    for r in results:
        ratio = f"{raw.per_hour / r.per_hour:.1f}x" if raw else "n/a"
        what = "records" if r.mode.startswith("fl-") else "samples"
        rows.append(
            f"| {r.mode} | {r.total:,} ({r.up:,} + {r.down:,}) | {r.per_hour / 1e6:.2f} | "
            f"{r.crossed:,} {what} of {r.published:,} | {ratio} |"
        )
    return "\n".join(rows)


def main() -> None:
    exit_on_sigterm()  # stopped with SIGTERM: the stack and the processes started here stop too
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--slice", type=float, default=150.0, help="replay the first SECONDS of the bag (0: all)")
    ap.add_argument("--speed", type=float, default=1.0, help="replay speed-up (1 = real time)")
    ap.add_argument("--modes", default=",".join(MODES), help=f"comma-separated, from {', '.join(MODES)}")
    ap.add_argument("--idle", type=float, default=2.0, help="seconds of idle link measured per mode")
    args = ap.parse_args()
    modes = [m for m in args.modes.split(",") if m]
    if not modes or set(modes) - set(MODES):
        raise SystemExit(f"--modes: choose from {', '.join(MODES)}")
    messages = load_bag(args.slice)
    print(
        f"bag: {len(messages):,} messages over {bag_seconds(messages):.1f} s, "
        f"{sum(len(m[2]) for m in messages):,} CDR bytes; speed {args.speed:g}; modes run side by side"
    )
    began = time.monotonic()
    with ExitStack() as stack, tempfile.TemporaryDirectory(prefix="fleetlink-wan-") as tmp:
        work = Path(tmp)
        bootstrap, registry = os.environ.get("KAFKA_BOOTSTRAP"), os.environ.get("SCHEMA_REGISTRY_URL")
        if any(m.startswith("fl-") for m in modes) and not (bootstrap and registry):
            local = LocalStack(work / "stack")
            info = local.start()
            stack.callback(local.stop)
            bootstrap, registry = info.bootstrap, info.registry_url

        def one(mode: str) -> Result:
            if mode.startswith("fl-"):
                return run_fleetlink(
                    mode,
                    messages,
                    args.speed,
                    args.idle,
                    bootstrap=bootstrap or "",
                    registry=registry or "",
                    work=work,
                )
            return run_raw(mode, messages, args.speed, args.idle)

        with ThreadPoolExecutor(max_workers=len(modes)) as pool:
            results = list(pool.map(one, modes))
    for r in results:
        print(f"{r.mode}: set-up {r.setup_bytes:,} B, idle {r.idle_bps:.1f} B/s; {r.detail}")
    print(f"\n{bag_seconds(messages):.1f} s of the bag, {time.monotonic() - began:.0f} s in all\n")
    print(table(results))


if __name__ == "__main__":
    main()
