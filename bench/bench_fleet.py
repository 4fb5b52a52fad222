"""Fleet benchmark: steady fleets of robots -> site router -> edge -> WAN -> uplink -> Kafka.

    .venv/bin/python bench/bench_fleet.py [--shape 200x5x10 ...] [--seconds 30] [--runs 2]

Each robot is its own Zenoh session (as an rmw_zenoh process is), publishing real recorded
messages on five topics (Imu, Odometry, NavSatFix from the Husky bag; LaserScan, JointState from
the TurtleBot3 bag) at a steady rate, evenly spread. As separate processes: the publishers (250
robots each), the site router, the edge agent (a client of the site router; durable spool,
at-least-once; default WAN settings), the uplink (also the cloud router; acks=all, idempotence),
a single-node Kafka and Apicurio Registry (started here, or ``$KAFKA_BOOTSTRAP`` /
``$SCHEMA_REGISTRY_URL``). Every topic is mapped many-to-one to a fleet-wide Kafka topic.

Per shape (``ROBOTSxTOPICSxHZ``; ``HZ`` 0 = subscribed and idle), over the steady window (after
``--warmup`` seconds): messages offered and delivered to Kafka (%), records/s, latency publish ->
record read from Kafka (p50/p99/max), CPU of the edge and the uplink in µs per record and in %
of a core, the edge's threads and RSS over time, samples dropped at the edge's intake and
sequence gaps (samples lost before the edge saw them).
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from confluent_kafka import Consumer, TopicPartition
from confluent_kafka.admin import AdminClient, NewTopic

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.bench_e2e import percentile, tree_cpu  # noqa: E402
from bench.fleet_publisher import TOPICS  # noqa: E402
from fleetlink.localstack.process import ServerProcess, exit_on_sigterm, free_port  # noqa: E402
from fleetlink.localstack.stack import LocalStack  # noqa: E402

ROBOTS_PER_PROCESS = 250


@dataclass(frozen=True)
class Shape:
    robots: int
    topics: int
    hz: float

    @classmethod
    def parse(cls, text: str) -> Shape:
        robots, topics, hz = text.split("x")
        return cls(int(robots), int(topics), float(hz))

    @property
    def name(self) -> str:
        return f"{self.robots} robots x {self.topics} topics x {self.hz:g} Hz"

    @property
    def rate(self) -> float:
        return self.robots * self.topics * self.hz


DEFAULT_SHAPES = ("200x5x10", "1000x5x2", "20x5x100", "8x1x625", "200x5x0")


def proc_status(pid: int) -> dict[str, str]:
    out = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, value = line.partition(":")
        out[key] = value.strip()
    return out


def rss_mb(pid: int) -> float:
    return int(proc_status(pid)["VmRSS"].split()[0]) / 1024


def threads(pid: int) -> int:
    return int(proc_status(pid)["Threads"])


@dataclass
class Sample:
    at: float
    cpu: dict[str, float]
    edge_rss_mb: float
    edge_threads: int


@dataclass
class Result:
    shape: Shape
    offered: int = 0
    delivered: int = 0
    window_records: int = 0
    window_s: float = 0.0
    latencies_ms: list[float] = field(default_factory=list)
    cpu_s: dict[str, float] = field(default_factory=dict)
    samples: list[Sample] = field(default_factory=list)
    dropped: int = 0
    gaps: int = 0
    missing: int = 0
    behind: int = 0
    batches: int = 0
    batch_records: int = 0

    def line(self) -> str:
        s = self.shape
        pct = 100.0 * self.delivered / self.offered if self.offered else float("nan")
        rate = self.window_records / self.window_s if self.window_s else 0.0
        parts = [f"{s.name}: offered {self.offered:,}, delivered {self.delivered:,} ({pct:.2f} %)"]
        if self.window_records:
            parts.append(f"{rate:,.0f} records/s")
            for proc in ("edge", "uplink"):
                cpu = self.cpu_s.get(proc, 0.0)
                per_record = 1e6 * cpu / self.window_records
                parts.append(
                    f"{proc} {per_record:.1f} µs/record ({100 * cpu / self.window_s:.0f} % of a core)"
                )
        else:
            for proc in ("edge", "uplink", "site router"):
                cpu = self.cpu_s.get(proc, 0.0)
                parts.append(f"{proc} {100 * cpu / max(self.window_s, 1e-9):.1f} % of a core (idle)")
        if self.latencies_ms:
            lat = self.latencies_ms
            parts.append(
                f"latency p50 {statistics.median(lat):.1f} ms, p99 {percentile(lat, 0.99):.1f} ms, "
                f"max {max(lat):.1f} ms"
            )
        rss = [x.edge_rss_mb for x in self.samples]
        if rss:
            third = max(1, len(rss) // 3)
            parts.append(
                f"edge threads {max(x.edge_threads for x in self.samples)}, RSS {rss[0]:.0f} -> "
                f"{statistics.mean(rss[third : 2 * third] or rss):.0f} -> {rss[-1]:.0f} MB"
            )
        others = ", ".join(
            f"{k} {100 * v / max(self.window_s, 1e-9):.0f} %"
            for k, v in self.cpu_s.items()
            if k not in ("edge", "uplink")
        )
        parts.append(f"CPU of the others: {others}")
        parts.append(f"intake drops {self.dropped}, sequence gaps {self.gaps} ({self.missing} missing)")
        if self.batches:
            parts.append(f"WAN batches of {self.batch_records / self.batches:.0f} records on average")
        if self.behind:
            parts.append(f"publishers behind schedule {self.behind}")
        return "; ".join(parts)


def create_topics(bootstrap: str, names: list[str]) -> None:
    admin = AdminClient({"bootstrap.servers": bootstrap})
    futures = admin.create_topics([NewTopic(n, num_partitions=1, replication_factor=1) for n in names])
    for f in futures.values():
        f.result(30)
    deadline = time.monotonic() + 30
    while not all(admin.list_topics(n, timeout=5).topics[n].partitions for n in names):
        if time.monotonic() > deadline:
            raise SystemExit("topics have no partitions after 30 s")
        time.sleep(0.05)


class Reader(threading.Thread):
    """Reads every record of the topics: (receive time, record timestamp ms)."""

    def __init__(self, bootstrap: str, topics: list[str]) -> None:
        super().__init__(daemon=True)
        self.consumer = Consumer(
            {
                "bootstrap.servers": bootstrap,
                "group.id": f"bench-{uuid.uuid4().hex}",
                "enable.auto.commit": False,
                "fetch.wait.max.ms": 5,
            }
        )
        self.consumer.assign([TopicPartition(t, 0, 0) for t in topics])
        self.got: list[tuple[float, int]] = []
        self.stop_event = threading.Event()

    def run(self) -> None:
        gc.freeze()
        while not self.stop_event.is_set():
            msgs = self.consumer.consume(2000, timeout=0.005)
            now = time.time()
            self.got.extend((now, m.timestamp()[1]) for m in msgs if m.error() is None)
        self.consumer.close()


def run_shape(
    work: Path, shape: Shape, bootstrap: str, registry: str, seconds: float, warmup: float
) -> Result:
    work.mkdir(parents=True)
    suffix = uuid.uuid4().hex[:6]
    topic_names = [f"bench.fleet.{name}.{suffix}" for name, *_ in TOPICS[: shape.topics]]
    create_topics(bootstrap, topic_names)
    cloud_port, site_port = free_port(), free_port()
    result = Result(shape)
    with ExitStack() as stack:
        procs: dict[str, int] = {}
        uplink = {
            "kafka": {"bootstrap_servers": bootstrap, "linger": "5ms"},
            "registry": {"url": registry},
            "zenoh": {"mode": "router", "listen": [f"tcp/127.0.0.1:{cloud_port}"]},
        }
        mappings = [
            {"name": name, "from": f"/{{robot}}/{name}", "to": topic, "type": typename}
            for (name, typename, _bag_topic, _bag), topic in zip(TOPICS, topic_names, strict=False)
        ]
        edge = {
            "site": "fleet",
            "edge_id": "edge-1",
            "zenoh": {"mode": "client", "connect": [f"tcp/127.0.0.1:{site_port}"]},
            "robot_types": {"bench": {"match": "/r*", "mappings": mappings}},
            "spool": {"dir": str(work / "spool"), "max_bytes": "1GiB"},
        }
        router = subprocess.Popen(
            [
                sys.executable,
                str(ROOT / "bench" / "fleet_router.py"),
                str(site_port),
                f"tcp/127.0.0.1:{cloud_port}",
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            cwd=ROOT,
        )
        stack.callback(router.wait, 30)
        stack.callback(router.stdin.close)  # type: ignore[union-attr]
        if router.stdout is None or router.stdout.readline().strip() != "ready":
            raise SystemExit("site router did not start")
        procs["site router"] = router.pid
        stats_path = work / "edge.stats"
        for name, config, argv in (
            ("uplink", uplink, ["uplink", "run"]),
            ("edge", edge, ["edge", "run", "--stats-file", str(stats_path)]),
        ):
            path = work / f"{name}.yaml"
            path.write_text(yaml.safe_dump(config))
            log = work / f"{name}.log"

            def ready(name: str = name, log: Path = log) -> bool:
                return stats_path.exists() if name == "edge" else "uplink running" in log.read_text()

            proc = ServerProcess(
                name=name,
                argv=[sys.executable, "-m", "fleetlink", *argv[:2], "-c", str(path), *argv[2:]],
                log_path=log,
                pid_path=work / f"{name}.pid",
                ready=ready,
            )
            proc.start(60)
            stack.callback(proc.stop)
            if proc.pid is None:
                raise SystemExit(f"{name} did not start")
            procs[name] = proc.pid

        pubs: list[subprocess.Popen[str]] = []
        for first in range(0, shape.robots, ROBOTS_PER_PROCESS):
            n = min(ROBOTS_PER_PROCESS, shape.robots - first)
            pub = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "bench.fleet_publisher",
                    "--connect",
                    f"tcp/127.0.0.1:{site_port}",
                    "--first",
                    str(first),
                    "--robots",
                    str(n),
                    "--topics",
                    str(shape.topics),
                    "--hz",
                    str(shape.hz),
                    "--seconds",
                    str(seconds),
                ],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                text=True,
                cwd=ROOT,
            )
            pubs.append(pub)
            stack.callback(pub.kill)
        for pub in pubs:
            if pub.stdout is None or pub.stdout.readline().strip() != "ready":
                raise SystemExit("a publisher did not start")
        want = shape.robots * shape.topics
        deadline = time.monotonic() + 300
        while True:  # every robot registered and every topic subscribed
            try:
                subs = json.loads(stats_path.read_text()).get("subscriptions", {})
            except (OSError, ValueError):
                subs = {}
            if len(subs) >= want:
                break
            if time.monotonic() > deadline:
                raise SystemExit(f"the edge subscribed {len(subs)} of {want} topics in 300 s")
            time.sleep(0.5)
        time.sleep(1.0)

        reader = Reader(bootstrap, topic_names)
        reader.start()
        samples: list[Sample] = []
        stop_sampling = threading.Event()

        def cpu_now() -> dict[str, float]:
            out = {name: tree_cpu(pid) for name, pid in procs.items()}
            out["robots"] = sum(tree_cpu(p.pid) for p in pubs)
            return out

        def sample() -> None:
            while not stop_sampling.wait(1.0):
                edge_pid = procs["edge"]
                samples.append(Sample(time.time(), cpu_now(), rss_mb(edge_pid), threads(edge_pid)))

        sampler = threading.Thread(target=sample, daemon=True)
        for pub in pubs:
            assert pub.stdin is not None
            pub.stdin.write("go\n")
            pub.stdin.flush()
        sampler.start()
        time.sleep(warmup)
        cpu0, t0 = cpu_now(), time.time()
        time.sleep(max(0.0, seconds - warmup))
        cpu1, t1 = cpu_now(), time.time()
        for pub in pubs:
            assert pub.stdout is not None
            done = pub.stdout.readline().split()
            result.offered += int(done[1])
            result.behind += int(done[3])
        deadline = time.monotonic() + 60
        while len(reader.got) < result.offered and time.monotonic() < deadline:
            time.sleep(0.2)
        time.sleep(0.5)
        stop_sampling.set()
        reader.stop_event.set()
        reader.join(10)
        stats = json.loads(stats_path.read_text())
        for pub in pubs:
            assert pub.stdin is not None
            pub.stdin.write("bye\n")
            pub.stdin.flush()
    result.delivered = len(reader.got)
    lo, hi = t0 * 1000, t1 * 1000
    window = [(recv, stamp) for recv, stamp in reader.got if lo <= stamp < hi]
    result.window_records = len(window)
    result.window_s = t1 - t0
    result.latencies_ms = [recv * 1000 - stamp for recv, stamp in window]
    result.cpu_s = {k: cpu1[k] - cpu0[k] for k in cpu1}
    result.samples = samples
    result.dropped = int(stats.get("intake", {}).get("dropped", 0))
    sender = stats.get("streams", {}).get("durable", {}).get("sender", {})
    if os.environ.get("BENCH_DEBUG"):
        print(
            "edge sender:", json.dumps(sender), "processor:", json.dumps(stats.get("processor")), flush=True
        )
    result.batches = int(sender.get("batches_sent", 0))
    result.batch_records = int(sender.get("records_sent", 0))
    subs = stats.get("subscriptions", {})
    result.gaps = sum(int(s.get("gaps", 0)) for s in subs.values())
    result.missing = sum(int(s.get("missing", 0)) for s in subs.values())
    return result


def main() -> None:
    exit_on_sigterm()
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--shape", action="append", help=f"ROBOTSxTOPICSxHZ (default: {' '.join(DEFAULT_SHAPES)})"
    )
    ap.add_argument("--seconds", type=float, default=30.0, help="how long the robots publish")
    ap.add_argument("--warmup", type=float, default=5.0, help="seconds not counted at the start")
    ap.add_argument("--runs", type=int, default=2, help="runs of each shape (this machine is noisy)")
    args = ap.parse_args()
    shapes = [Shape.parse(s) for s in (args.shape or DEFAULT_SHAPES)]
    with ExitStack() as stack, tempfile.TemporaryDirectory(prefix="fleetlink-fleet-") as tmp:
        work = Path(tmp)
        bootstrap, registry = os.environ.get("KAFKA_BOOTSTRAP"), os.environ.get("SCHEMA_REGISTRY_URL")
        if not (bootstrap and registry):
            local = LocalStack(work / "stack")
            info = local.start()
            stack.callback(local.stop)
            bootstrap, registry = info.bootstrap, info.registry_url
        print(
            f"{os.cpu_count()} CPUs; {args.seconds:g} s per run, the first {args.warmup:g} s not counted",
            flush=True,
        )
        for shape in shapes:
            for run in range(args.runs):
                result = run_shape(
                    work / f"{shape.robots}-{shape.topics}-{shape.hz:g}-{run}",
                    shape,
                    bootstrap,
                    registry,
                    args.seconds,
                    args.warmup,
                )
                print(f"run {run + 1}: {result.line()}", flush=True)


if __name__ == "__main__":
    main()
