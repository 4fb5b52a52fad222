"""End-to-end benchmark: robots → edge agent → WAN → uplink → Kafka, against the direct path.

    .venv/bin/python bench/bench_e2e.py [--robots 8] [--records 40000] [--repeat 3] [--latency-rate 1000]

Starts Kafka + Apicurio (or uses $KAFKA_BOOTSTRAP / $SCHEMA_REGISTRY_URL), then as separate
processes: the uplink (also the cloud Zenoh router), the edge agent (also the site router,
durable spool, at-least-once) and the robots (real Husky IMU messages over rmw_zenoh). Prints:

1. throughput: records/s from the first publish to the last record read back from Kafka, with
   the CPU seconds each process used (and the broker's, when the bench started it); the robots
   publish everything at once, so the figure includes filling the pipeline and registering the
   schema of a new topic;
2. latency at a steady rate: source timestamp (set at publish) → record read from Kafka, p50/p99,
   over all records and over those after the first ``--warmup`` seconds;
3. the original design's direct path in one process, same messages: rosbags deserialize →
   dict → fastavro → Kafka produce (no spool, no acknowledgements), and the ratio.

Method: ``--warmup-rounds`` rounds of parts 1 and 3 run first and are printed but not counted
(a freshly started broker's JVM is cold: it charged the first rounds up to twice the broker CPU
of a warm one); then parts 1 and 3 alternate ``--repeat`` times and their medians are compared
(the machine's other load varies); every Kafka topic is created before its run; records are
read back one ``poll`` at a time for latency (receive times to the millisecond), in 5 ms batches
for throughput. Part 2 runs last. Environment: ``BENCH_LINGER`` (the edge's ``wan.linger``, default 10ms),
``BENCH_KAFKA_LINGER`` / ``BENCH_KAFKA_COMPRESSION`` (the uplink's ``kafka.linger`` and
``kafka.compression``; default: the uplink's, lz4 and 1 ms),
``BENCH_METRICS=1`` (the uplink's Prometheus metrics on: every delivery report counted).
"""

from __future__ import annotations

import argparse
import gc
import io
import os
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import fastavro
import yaml
from confluent_kafka import Consumer, Producer, TopicPartition
from confluent_kafka.admin import AdminClient, NewTopic
from rosbags.typesys import Stores, get_typestore

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.e2e_publisher import IMU, imu_payloads  # noqa: E402
from fleetlink.localstack.process import (  # noqa: E402
    ServerProcess,
    exit_on_sigterm,
    free_port,
)
from fleetlink.localstack.stack import LocalStack  # noqa: E402
from fleetlink.schemas.codec import get_codec  # noqa: E402
from fleetlink.schemas.registry import SchemaRegistry  # noqa: E402
from fleetlink.schemas.single_object import confluent_frame  # noqa: E402
from fleetlink.schemas.typestore import load_typestore  # noqa: E402

CLK = os.sysconf("SC_CLK_TCK")


def tree_cpu(pid: int) -> float:
    """CPU seconds (user + system) of the whole process: /proc/<pid>/stat counts every thread,
    also those that ended (summing /proc/<pid>/task/* would miss them, and race their exit)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK  # utime + stime


def steal_s() -> float:
    """CPU seconds the hypervisor took from this VM's processors since boot (``/proc/stat``'s
    ``steal``, all processors): time the machine's work was ready and did not run."""
    fields = Path("/proc/stat").read_text().split("\n", 1)[0].split()
    return int(fields[8]) / CLK if len(fields) > 8 else 0.0


def uplink_kafka(bootstrap: str) -> dict[str, Any]:
    """The uplinks' ``kafka`` section: ``BENCH_KAFKA_LINGER`` and ``BENCH_KAFKA_COMPRESSION`` where
    set, else the uplink's defaults."""
    kafka: dict[str, Any] = {"bootstrap_servers": bootstrap}
    for key in ("linger", "compression"):
        value = os.environ.get(f"BENCH_KAFKA_{key.upper()}")
        if value:
            kafka[key] = value
    return kafka


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def create_topic(bootstrap: str, prefix: str) -> str:
    """A new one-partition topic, created before the run: the broker creating it on the first
    produce (~0.1 s) and a consumer noticing it (up to its metadata refresh) are not per-record
    costs of either path."""
    topic = f"{prefix}.{uuid.uuid4().hex[:6]}"
    admin = AdminClient({"bootstrap.servers": bootstrap})
    admin.create_topics([NewTopic(topic, num_partitions=1, replication_factor=1)])[topic].result(30)
    deadline = time.monotonic() + 30
    while not admin.list_topics(topic, timeout=5).topics[topic].partitions:
        if time.monotonic() > deadline:
            raise SystemExit(f"topic {topic} has no partition after 30 s")
        time.sleep(0.05)
    return topic


def read_topic(
    bootstrap: str, topic: str, count: int, timeout: float, *, per_record: bool = True
) -> list[tuple[float, int]]:
    """(receive time, record timestamp ms) for ``count`` records of a one-partition topic.

    ``per_record``: one ``poll`` per record, receive times exact (latency). Otherwise batches of
    up to 1,000 with a 5 ms timeout: times within 5 ms, and the reader (which shares the CPUs
    with what it measures) costs a fraction. Never ``consume(n, 0.1)``: it returns only when
    ``n`` records are there or the timeout is over, adding up to 0.1 s to receive times.
    """
    consumer = Consumer(
        {
            "bootstrap.servers": bootstrap,
            "group.id": f"bench-{uuid.uuid4().hex}",
            "enable.auto.commit": False,
            "topic.metadata.refresh.interval.ms": 200,
            "fetch.wait.max.ms": 5,
        }
    )
    consumer.assign([TopicPartition(topic, 0, 0)])
    out: list[tuple[float, int]] = []
    gc.freeze()  # a full collection of this process (payloads, type store) would delay receive times
    deadline = time.monotonic() + timeout
    try:
        while len(out) < count and time.monotonic() < deadline:
            if per_record:
                msg = consumer.poll(0.1)
                if msg is not None and msg.error() is None:
                    out.append((time.time(), msg.timestamp()[1]))
                continue
            msgs = consumer.consume(1000, timeout=0.005)
            now = time.time()
            out.extend((now, m.timestamp()[1]) for m in msgs if m.error() is None)
    finally:
        consumer.close()
    return out


class Pipeline:
    """Uplink (cloud router) + edge agent (site router) as processes."""

    def __init__(
        self,
        work: Path,
        bootstrap: str,
        registry: str,
        topic: str,
        stack: ExitStack,
        delivery: str = "at_least_once",
    ) -> None:
        self.cloud_port, self.site_port = free_port(), free_port()
        uplink: dict[str, Any] = {
            "kafka": uplink_kafka(bootstrap),
            "registry": {"url": registry},
            "zenoh": {"mode": "router", "listen": [f"tcp/127.0.0.1:{self.cloud_port}"]},
        }
        if os.environ.get("BENCH_METRICS"):  # Prometheus metrics on: every delivery report counted
            uplink["metrics"] = {"listen": "127.0.0.1:0"}
        edge = {
            "site": "bench",
            "edge_id": "edge-1",
            "zenoh": {
                "mode": "router",
                "listen": [f"tcp/127.0.0.1:{self.site_port}"],
                "connect": [f"tcp/127.0.0.1:{self.cloud_port}"],
            },
            "robot_types": {
                "bench": {
                    "match": "/r*",
                    "mappings": [{"name": "imu", "from": "/{robot}/imu", "to": topic, "type": IMU}],
                }
            },
            "spool": {
                "dir": str(work / "spool"),
                "max_bytes": "1GiB",
                "fsync": "interval",
                "delivery": delivery,
            },
            "wan": {
                "batch_max_records": 2000,
                "linger": os.environ.get("BENCH_LINGER", "10ms"),
                "max_in_flight": 4,
                "codec": "zstd",
            },
        }
        self.procs: dict[str, ServerProcess] = {}
        for name, config, argv in (
            ("uplink", uplink, ["uplink", "run"]),
            ("edge", edge, ["edge", "run"]),
        ):
            path = work / f"{name}.yaml"
            path.write_text(yaml.safe_dump(config))
            log = work / f"{name}.log"
            marker = work / f"{name}.ready"
            extra = ["--stats-file", str(marker)] if name == "edge" else []

            def uplink_up(log: Path = log) -> bool:
                return "uplink running" in log.read_text()

            proc = ServerProcess(
                name=name,
                argv=[sys.executable, "-m", "fleetlink", *argv, "-c", str(path), *extra],
                log_path=log,
                pid_path=work / f"{name}.pid",
                ready=marker.exists if name == "edge" else uplink_up,
            )
            proc.start(60)
            stack.callback(proc.stop)
            self.procs[name] = proc

    def cpu(self) -> dict[str, float]:
        return {name: tree_cpu(p.pid) for name, p in self.procs.items() if p.pid}


def run_robots(site_port: int, robots: int, count: int, rate: float) -> tuple[subprocess.Popen[str], float]:
    pub = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "bench.e2e_publisher",
            "--connect",
            f"tcp/127.0.0.1:{site_port}",
            "--robots",
            str(robots),
            "--count",
            str(count),
            "--rate",
            str(rate),
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    if pub.stdout is None or pub.stdin is None:
        raise SystemExit("publisher has no pipes")
    if pub.stdout.readline().strip() != "ready":
        raise SystemExit("publisher did not start")
    time.sleep(3.0)  # let the edge discover the robots and subscribe (discovery is asynchronous)
    began = time.time()
    pub.stdin.write("go\n")
    pub.stdin.flush()
    return pub, began


def direct_path(bootstrap: str, registry: str, payloads: list[bytes], n: int) -> float:
    """The original system's path: deserialize → dict → fastavro → produce, one process."""
    ts = get_typestore(Stores.ROS2_JAZZY)
    schema = get_codec(load_typestore("jazzy"), IMU, "jazzy").schema
    parsed = fastavro.parse_schema(schema)
    topic = create_topic(bootstrap, "bench.direct")
    with SchemaRegistry(registry) as reg:
        schema_id = reg.register(f"{topic}-value", schema)

    def to_dict(obj: Any) -> Any:
        if hasattr(obj, "__dataclass_fields__"):
            return {k: to_dict(getattr(obj, k)) for k in obj.__dataclass_fields__ if k != "__msgtype__"}
        if hasattr(obj, "tolist"):
            return obj.tolist()
        return obj

    producer = Producer({"bootstrap.servers": bootstrap, "linger.ms": 5})
    began = time.perf_counter()
    for i in range(n):
        msg = ts.deserialize_cdr(payloads[i % len(payloads)], IMU)
        buf = io.BytesIO()
        fastavro.schemaless_writer(buf, parsed, to_dict(msg))
        while True:
            try:
                value = confluent_frame(schema_id, buf.getvalue())
                producer.produce(topic, key=b"r%02d" % (i % 8), value=value)
                break
            except BufferError:
                producer.poll(0.01)
        producer.poll(0)
    producer.flush(60)
    return n / (time.perf_counter() - began)


def latency_line(lat: list[float]) -> str:
    return f"p50 {statistics.median(lat):.1f} ms   p99 {percentile(lat, 0.99):.1f} ms   max {max(lat):.1f} ms"


@dataclass
class Throughput:
    got: int
    elapsed: float
    published: int
    publish_s: float
    cpu: dict[str, float]

    @property
    def rate(self) -> float:
        return self.got / self.elapsed


def run_throughput(
    work: Path,
    bootstrap: str,
    registry: str,
    robots: int,
    per_robot: int,
    broker_pid: int | None,
    delivery: str = "at_least_once",
) -> Throughput:
    """The robots publish ``per_robot`` messages each at once; first publish -> last record read
    (read committed: with ``exactly_once`` a record counts once its transaction committed)."""
    topic = create_topic(bootstrap, "bench.imu")
    work.mkdir()
    with ExitStack() as stack:
        pipe = Pipeline(work, bootstrap, registry, topic, stack, delivery)
        cpu0 = pipe.cpu()
        broker0 = tree_cpu(broker_pid) if broker_pid else 0.0
        steal0 = steal_s()
        pub, began = run_robots(pipe.site_port, robots, per_robot, 0)
        got = read_topic(bootstrap, topic, per_robot * robots, timeout=300, per_record=False)
        steal = steal_s() - steal0
        if pub.stdout is None or pub.stdin is None:
            raise SystemExit("publisher has no pipes")
        published = pub.stdout.readline().split()
        cpu = {"robots": tree_cpu(pub.pid)}
        pub.stdin.write("bye\n")
        pub.stdin.flush()
        pub.wait(30)
        cpu1 = pipe.cpu()
        cpu.update({k: cpu1[k] - cpu0[k] for k in cpu1})
        if broker_pid:
            cpu["Kafka broker"] = tree_cpu(broker_pid) - broker0
        cpu["VM steal"] = steal  # taken from every process alike: a stall of the whole machine
    elapsed = got[-1][0] - began if got else float("nan")
    return Throughput(len(got), elapsed, int(published[1]), float(published[2]), cpu)


def run_latency(
    work: Path, bootstrap: str, registry: str, robots: int, rate: float, seconds: float
) -> list[tuple[float, int]]:
    topic = create_topic(bootstrap, "bench.imu.lat")
    work.mkdir()
    with ExitStack() as stack:
        pipe = Pipeline(work, bootstrap, registry, topic, stack)
        n = int(rate * seconds) // robots
        pub, _ = run_robots(pipe.site_port, robots, n, rate)
        got = read_topic(bootstrap, topic, n * robots, timeout=120)
        if pub.stdin is None:
            raise SystemExit("publisher has no pipes")
        pub.stdin.write("bye\n")
        pub.stdin.flush()
        pub.wait(60)
    return got


def main() -> None:
    exit_on_sigterm()  # stopped with SIGTERM: the stack and the processes started here stop too
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robots", type=int, default=8)
    ap.add_argument("--records", type=int, default=40_000, help="total records for the throughput run")
    ap.add_argument(
        "--repeat",
        type=int,
        default=3,
        help="throughput rounds, fleetlink and the direct path alternating (medians compared)",
    )
    ap.add_argument(
        "--warmup-rounds",
        type=int,
        default=1,
        help="rounds of both run first and not counted (a fresh broker's JVM is still cold)",
    )
    ap.add_argument("--latency-rate", type=float, default=1000.0)
    ap.add_argument("--latency-seconds", type=float, default=10.0)
    ap.add_argument(
        "--warmup",
        type=float,
        default=1.0,
        help="seconds at the start of the latency run also reported apart (schema registration, "
        "first batches)",
    )
    ap.add_argument(
        "--only",
        choices=("throughput", "exactly_once", "latency", "direct"),
        action="append",
        help="run only these parts (repeatable; default: all four)",
    )
    args = ap.parse_args()
    parts = set(args.only or ("throughput", "exactly_once", "latency", "direct"))

    with ExitStack() as stack, tempfile.TemporaryDirectory(prefix="fleetlink-bench-") as tmp:
        work = Path(tmp)
        bootstrap, registry = os.environ.get("KAFKA_BOOTSTRAP"), os.environ.get("SCHEMA_REGISTRY_URL")
        broker_pid: int | None = None
        if not (bootstrap and registry):
            local = LocalStack(work / "stack")
            info = local.start()
            stack.callback(local.stop)
            bootstrap, registry, broker_pid = info.bootstrap, info.registry_url, info.kafka_pid
        payloads = imu_payloads(2000)
        print(f"Imu CDR record: {len(payloads[0])} bytes; robots: {args.robots}; {os.cpu_count()} CPUs")
        per_robot = args.records // args.robots
        total = per_robot * args.robots

        rates: list[float] = []
        directs: list[float] = []
        exact: list[float] = []
        if parts & {"throughput", "direct"}:
            print(
                f"\n1. throughput, {total} records, at-least-once (durable spool, acked WAN batches, "
                "acks=all), against 3. the direct path (one process: rosbags → dict → fastavro → "
                "produce; no spool, no acks), alternating:"
            )
        for i in range(-args.warmup_rounds, args.repeat):
            line = f"   round {i + 1}:" if i >= 0 else "   warm-up (not counted):"
            if "throughput" in parts:
                t = run_throughput(
                    work / f"tp{i + args.warmup_rounds}",
                    bootstrap,
                    registry,
                    args.robots,
                    per_robot,
                    broker_pid,
                )
                rates.append(t.rate)
                line += (
                    f" fleetlink {t.got}/{total} in {t.elapsed:.2f} s = {t.rate:,.0f} records/s"
                    f" (robots published in {t.publish_s:.2f} s; CPU s: "
                    + ", ".join(f"{k} {v:.1f}" for k, v in t.cpu.items())
                    + ")"
                )
            if "exactly_once" in parts:
                e = run_throughput(
                    work / f"eo{i + args.warmup_rounds}",
                    bootstrap,
                    registry,
                    args.robots,
                    per_robot,
                    broker_pid,
                    "exactly_once",
                )
                exact.append(e.rate)
                line += f" | exactly once {e.got}/{total} = {e.rate:,.0f} records/s (CPU s: " + ", ".join(
                    f"{k} {v:.1f}" for k, v in e.cpu.items()
                )
                line += ")"
            if "direct" in parts:
                directs.append(direct_path(bootstrap, registry, payloads, total))
                line += f" | direct {directs[-1]:,.0f} records/s"
            if rates and directs:
                line += f" | ratio {rates[-1] / directs[-1]:.2f}"
            print(line, flush=True)
            if i < 0:
                rates.clear()
                directs.clear()
                exact.clear()
        if rates:
            print(f"   fleetlink end to end, median: {statistics.median(rates):,.0f} records/s")
        if exact:
            print(f"   exactly once end to end, median: {statistics.median(exact):,.0f} records/s")
            if rates:
                print(
                    "   exactly once / at least once (medians): "
                    f"{statistics.median(exact) / statistics.median(rates):.2f}"
                )
        if directs:
            print(f"   direct path, median: {statistics.median(directs):,.0f} records/s")
        if rates and directs:
            print(
                f"\nratio fleetlink end to end / direct path (medians): "
                f"{statistics.median(rates) / statistics.median(directs):.2f}"
            )

        if "latency" in parts:
            got = run_latency(
                work / "lat", bootstrap, registry, args.robots, args.latency_rate, args.latency_seconds
            )
            lat = [(recv * 1000 - stamp) for recv, stamp in got]
            first = min(stamp for _recv, stamp in got)
            steady = [(recv * 1000 - stamp) for recv, stamp in got if stamp - first >= args.warmup * 1000]
            print(
                f"\n2. latency at {args.latency_rate:,.0f} records/s (publish → record read from Kafka), "
                f"{len(lat)} records:"
            )
            print(f"   all records:            {latency_line(lat)}")
            if steady:
                print(f"   after the first {args.warmup:g} s ({len(steady)} records): {latency_line(steady)}")


if __name__ == "__main__":
    main()
