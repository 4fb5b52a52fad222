"""Fleet benchmark: steady fleets of robots -> site router -> edge -> WAN -> uplink -> Kafka.

    .venv/bin/python bench/bench_fleet.py [--shape 200x5x10 ...] [--seconds 30] [--runs 2]
        [--sites 10] [--uplinks 2] [--bare]

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
sequence gaps (samples lost before the edge saw them), and the CPU time the hypervisor took
from the machine (``/proc/stat``'s steal: in all, and its worst second, to set beside the worst
second of latency: a stall every process shares). With ``--uplinks N`` the cloud router is
a process of its own and N uplinks serve the sites (each site's stream goes to one of them):
each uplink's share of the CPU shows how they split the load. With ``--bare`` a bare Zenoh client
of each site router (bench/bare_receiver.py: the data plane's runtime, the same samples, nothing
done with them) runs beside the edge: its CPU is the floor of receiving the fleet through Zenoh
on this machine, printed beside the edge's as a ratio, with both processes' wake-ups a second.
``BENCH_KAFKA_LINGER`` / ``BENCH_KAFKA_COMPRESSION`` set the uplinks' ``kafka.linger`` and
``kafka.compression`` (default: the uplink's).

Before the counted runs, ``--warmup-runs`` runs of the first shape are printed but not counted: a
Kafka broker just started compiles its hot paths under the first minutes of load (200 x 5 x 10 Hz
on a fresh broker: p99 212 ms in the first run, 96 ms in the second, 61 ms once warm).
"""

from __future__ import annotations

import argparse
import gc
import itertools
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Mapping
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from confluent_kafka import Consumer, TopicPartition
from confluent_kafka.admin import AdminClient, NewTopic

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.bench_e2e import percentile, steal_s, tree_cpu, uplink_kafka  # noqa: E402
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


DEFAULT_SHAPES = ("200x5x10", "1000x5x2", "20x5x100", "8x1x625", "200x5x2", "200x5x0")


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


def wakeups(pid: int) -> int:
    """Times the process's threads went to sleep and were woken (voluntary context switches of
    the threads alive now): at steady low rates each costs more than the work it wakes for."""
    total = 0
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            status = (task / "status").read_text()
        except OSError:  # the thread ended
            continue
        total += int(status.split("voluntary_ctxt_switches:", 1)[1].split()[0])
    return total


@dataclass
class Sample:
    at: float
    cpu: dict[str, float]
    edge_rss_mb: float
    edge_threads: int
    steal_s: float


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
    sites: int = 1
    registered: list[int] = field(default_factory=list)
    """Robots each site's edge registered."""
    misrouted: int = 0
    """Robots whose records in Kafka name another site than the one they publish at (or several)."""
    uplink_cpu: list[float] = field(default_factory=list)
    """CPU seconds of each uplink over the window (with several)."""
    worst_second: tuple[float, float] | None = None
    """The second of the window (from its start) whose records had the highest p99 latency."""
    wakeups: dict[str, float] = field(default_factory=dict)
    """Wake-ups a second over the window of the edges and (``--bare``) the bare receivers."""
    steal_s: float = 0.0
    """CPU seconds the hypervisor took from the machine over the window (``steal_s``)."""
    steal_peak: tuple[float, float] | None = None
    """The second of the window with the most steal: ``(seconds from its start, steal s)``."""

    def line(self) -> str:
        s = self.shape
        pct = 100.0 * self.delivered / self.offered if self.offered else float("nan")
        rate = self.window_records / self.window_s if self.window_s else 0.0
        where = f" at {self.sites} sites" if self.sites > 1 else ""
        parts = [f"{s.name}{where}: offered {self.offered:,}, delivered {self.delivered:,} ({pct:.2f} %)"]
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
        bare = self.cpu_s.get("bare")
        if bare is not None and self.window_records:
            edge = self.cpu_s.get("edge", 0.0)
            parts.append(
                f"bare Zenoh receive {1e6 * bare / self.window_records:.1f} µs/record "
                f"({100 * bare / self.window_s:.0f} % of a core), edge / bare {edge / max(bare, 1e-9):.2f}"
            )
        if self.wakeups:
            parts.append("wake-ups/s " + ", ".join(f"{k} {v:,.0f}" for k, v in self.wakeups.items()))
        if self.latencies_ms:
            lat = self.latencies_ms
            parts.append(
                f"latency p50 {statistics.median(lat):.1f} ms, p99 {percentile(lat, 0.99):.1f} ms, "
                f"max {max(lat):.1f} ms"
            )
            if self.worst_second:
                at, p99 = self.worst_second
                parts.append(f"worst second +{at:.0f} s (p99 {p99:.0f} ms)")
        if self.window_s:
            steal = f"VM steal {100 * self.steal_s / self.window_s:.1f} % of a core"
            if self.steal_peak:
                at, most = self.steal_peak
                steal += f", most {1000 * most:.0f} ms in the second at +{at:.0f} s"
            parts.append(steal)
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
            if k not in ("edge", "uplink", "bare")
        )
        parts.append(f"CPU of the others: {others}")
        parts.append(f"intake drops {self.dropped}, sequence gaps {self.gaps} ({self.missing} missing)")
        if self.batches:
            parts.append(f"WAN batches of {self.batch_records / self.batches:.0f} records on average")
        if self.behind:
            parts.append(f"publishers behind schedule {self.behind}")
        if len(self.uplink_cpu) > 1:
            shares = " / ".join(f"{100 * c / max(self.window_s, 1e-9):.0f} %" for c in self.uplink_cpu)
            parts.append(f"uplinks' CPU {shares} of a core")
        if self.sites > 1:
            parts.append(
                f"robots registered per site {'/'.join(map(str, self.registered))}, "
                f"robots misrouted {self.misrouted}"
            )
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
        self.sites: dict[bytes, set[bytes]] = {}
        """Robot (the record key) -> the ``fleetlink.site`` headers its records carried."""
        self.stop_event = threading.Event()

    def run(self) -> None:
        gc.freeze()
        while not self.stop_event.is_set():
            msgs = self.consumer.consume(2000, timeout=0.005)
            now = time.time()
            for m in msgs:
                if m.error() is not None:
                    continue
                self.got.append((now, m.timestamp()[1]))
                key = m.key() or b""
                if key not in self.sites or len(self.sites[key]) == 1:
                    site = dict(m.headers() or ()).get("fleetlink.site", b"")
                    self.sites.setdefault(key, set()).add(site or b"")
        self.consumer.close()


def start_site(
    stack: ExitStack,
    work: Path,
    site: int,
    sites: int,
    cloud_port: int,
    mappings: list[dict[str, str]],
    intake: dict[str, str] | None = None,
) -> tuple[int, int, int, Path]:
    """One site: its router and its edge (a client of it). Returns (router port, router pid, edge
    pid, the edge's stats file)."""
    site_port = free_port()
    router_pid = start_router(
        stack,
        work / f"site-router-{site}.json5",
        ["edge-router-dev.json5", "--site", f"site-{site:02d}", "-e", f"tcp/127.0.0.1:{cloud_port}"],
        site_port,
    )
    name = "fleet" if sites == 1 else f"site-{site:02d}"
    edge = {
        "site": name,
        "edge_id": f"edge-{site}",
        "zenoh": {"mode": "client", "connect": [f"tcp/127.0.0.1:{site_port}"]},
        "robot_types": {"bench": {"match": "/r*", "mappings": mappings}},
        "spool": {"dir": str(work / f"spool-{site}"), "max_bytes": "1GiB"},
    }
    if intake:
        edge["intake"] = intake
    stats_path = work / f"edge-{site}.stats"
    pid = start_process(
        stack,
        work,
        f"edge-{site}",
        edge,
        ["edge", "run", "--stats-file", str(stats_path), "--stats-interval", "5"],
        stats_path.exists,
    )
    return site_port, router_pid, pid, stats_path


def start_router(stack: ExitStack, config: Path, render: list[str], port: int) -> int:
    """A router from a shipped template (``render``: the template's name in deploy/zenoh and
    ``fleetlink zenoh render`` options), listening on ``port``; returns its pid once it listens."""
    fleetlink = [sys.executable, "-m", "fleetlink", "zenoh"]
    template, *options = render
    listen = f"tcp/127.0.0.1:{port}"
    subprocess.run(
        [
            *fleetlink,
            "render",
            str(ROOT / "deploy" / "zenoh" / template),
            *options,
            "-l",
            listen,
            "-o",
            str(config),
        ],
        check=True,
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
    )
    router = subprocess.Popen(
        [*fleetlink, "router", "-c", str(config)],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    stack.callback(router.wait, 30)
    stack.callback(router.terminate)
    deadline = time.monotonic() + 30
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return router.pid
        except OSError:
            if time.monotonic() > deadline or router.poll() is not None:
                raise SystemExit(f"the router of {config.name} did not start") from None
            time.sleep(0.1)


def start_bare(stack: ExitStack, port: int, topics: int) -> int:
    """A bare receiver (bench/bare_receiver.py) of the site router on ``port``; its pid once it
    subscribed."""
    names = [arg for name, *_ in TOPICS[:topics] for arg in ("--topic", name)]
    proc = subprocess.Popen(
        [sys.executable, "-m", "bench.bare_receiver", "--connect", f"tcp/127.0.0.1:{port}", *names],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    stack.callback(proc.kill)
    if proc.stdout is None or proc.stdout.readline().strip() != "ready":
        raise SystemExit("the bare receiver did not start")
    return proc.pid


def start_process(
    stack: ExitStack, work: Path, name: str, config: Mapping[str, object], argv: list[str], ready: object
) -> int:
    path = work / f"{name}.yaml"
    path.write_text(yaml.safe_dump(config))
    proc = ServerProcess(
        name=name,
        argv=[sys.executable, "-m", "fleetlink", *argv[:2], "-c", str(path), *argv[2:]],
        log_path=work / f"{name}.log",
        pid_path=work / f"{name}.pid",
        ready=ready,  # type: ignore[arg-type]
    )
    proc.start(60)
    stack.callback(proc.stop)
    if proc.pid is None:
        raise SystemExit(f"{name} did not start")
    return proc.pid


def run_shape(
    work: Path,
    shape: Shape,
    bootstrap: str,
    registry: str,
    seconds: float,
    warmup: float,
    sites: int = 1,
    uplinks: int = 1,
    intake: dict[str, str] | None = None,
    bare: bool = False,
    robot_tick_s: float = 0.002,
) -> Result:
    work.mkdir(parents=True)
    suffix = uuid.uuid4().hex[:6]
    topic_names = [f"bench.fleet.{name}.{suffix}" for name, *_ in TOPICS[: shape.topics]]
    create_topics(bootstrap, topic_names)
    cloud_port = free_port()
    result = Result(shape, sites=sites)
    with ExitStack() as stack:
        procs: dict[str, int] = {}
        cloud = f"tcp/127.0.0.1:{cloud_port}"
        zenoh: dict[str, object] = {"mode": "router", "listen": [cloud]}  # the uplink is the cloud router
        if sites > 1 or uplinks > 1:
            # a cloud router of its own, from the shipped template: only fleetlink/** crosses it,
            # so each site's robots stay on their site (a router without it would route every
            # site's robot data to every edge subscribing to the same wildcard)
            procs["cloud router"] = start_router(
                stack, work / "cloud-router.json5", ["cloud-router-dev.json5"], cloud_port
            )
            zenoh = {"mode": "client", "connect": [cloud]}
        kafka = uplink_kafka(bootstrap)
        for n in range(uplinks):
            name = "uplink" if uplinks == 1 else f"uplink {n}"
            uplink = {
                "id": f"bench-uplink-{n}",
                "kafka": kafka,
                "registry": {"url": registry},
                "zenoh": zenoh,
            }
            uplink_log = work / f"{name}.log"
            procs[name] = start_process(
                stack,
                work,
                name,
                uplink,
                ["uplink", "run"],
                lambda log=uplink_log: "uplink running" in log.read_text(),
            )
        mappings = [
            {"name": name, "from": f"/{{robot}}/{name}", "to": topic, "type": typename}
            for (name, typename, _bag_topic, _bag), topic in zip(TOPICS, topic_names, strict=False)
        ]
        site_ports: list[int] = []
        stats_paths: list[Path] = []
        edges: list[int] = []
        for site in range(sites):
            port, router_pid, edge_pid, stats_path = start_site(
                stack, work, site, sites, cloud_port, mappings, intake
            )
            site_ports.append(port)
            stats_paths.append(stats_path)
            edges.append(edge_pid)
            procs[f"site router {site}"] = router_pid
            procs[f"edge {site}"] = edge_pid
        bares = [start_bare(stack, port, shape.topics) for port in site_ports] if bare else []
        procs.update({f"bare {site}": pid for site, pid in enumerate(bares)})

        pubs: list[subprocess.Popen[str]] = []
        robot_site: dict[bytes, str] = {}
        per_site = -(-shape.robots // sites)
        for site, port in enumerate(site_ports):
            lo, hi = site * per_site, min(shape.robots, (site + 1) * per_site)
            robot_site.update(
                {f"r{i:04d}".encode(): "fleet" if sites == 1 else f"site-{site:02d}" for i in range(lo, hi)}
            )
            for first in range(lo, hi, ROBOTS_PER_PROCESS):
                n = min(ROBOTS_PER_PROCESS, hi - first)
                pub = subprocess.Popen(
                    [
                        sys.executable,
                        "-m",
                        "bench.fleet_publisher",
                        "--connect",
                        f"tcp/127.0.0.1:{port}",
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
                        "--tick",
                        str(robot_tick_s),
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
            subscribed = sum(len(read_stats(path).get("subscriptions", {})) for path in stats_paths)
            if subscribed >= want:
                break
            if time.monotonic() > deadline:
                raise SystemExit(f"the edges subscribed {subscribed} of {want} topics in 300 s")
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
                rss = sum(rss_mb(pid) for pid in edges)
                samples.append(
                    Sample(time.time(), cpu_now(), rss, max(threads(pid) for pid in edges), steal_s())
                )

        sampler = threading.Thread(target=sample, daemon=True)
        for pub in pubs:
            assert pub.stdin is not None
            pub.stdin.write("go\n")
            pub.stdin.flush()
        sampler.start()
        time.sleep(warmup)
        woken = {"edge": edges, "bare": bares}
        wake0 = {k: sum(wakeups(pid) for pid in pids) for k, pids in woken.items() if pids}
        cpu0, t0, steal0 = cpu_now(), time.time(), steal_s()
        time.sleep(max(0.0, seconds - warmup))
        cpu1, t1, steal1 = cpu_now(), time.time(), steal_s()
        result.steal_s = steal1 - steal0
        wake1 = {k: sum(wakeups(pid) for pid in pids) for k, pids in woken.items() if pids}
        result.wakeups = {k: (wake1[k] - wake0[k]) / (t1 - t0) for k in wake1}
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
        all_stats = [read_stats(path) for path in stats_paths]
        for pub in pubs:
            assert pub.stdin is not None
            pub.stdin.write("bye\n")
            pub.stdin.flush()
    result.delivered = len(reader.got)
    lo_ms, hi_ms = t0 * 1000, t1 * 1000
    window = [(recv, stamp) for recv, stamp in reader.got if lo_ms <= stamp < hi_ms]
    result.window_records = len(window)
    result.window_s = t1 - t0
    result.latencies_ms = [recv * 1000 - stamp for recv, stamp in window]
    result.worst_second = worst_second(window, lo_ms)
    if os.environ.get("BENCH_DEBUG"):
        print("latency p50/p99 ms per 5 s:", timeline(window, lo_ms), flush=True)
    cpu = {k: cpu1[k] - cpu0[k] for k in cpu1}
    result.cpu_s = {
        "edge": sum(v for k, v in cpu.items() if k.startswith("edge ")),
        "site router": sum(v for k, v in cpu.items() if k.startswith("site router ")),
        **{k: v for k, v in cpu.items() if not k.startswith(("edge ", "site router ", "uplink ", "bare "))},
    }
    if bares:
        result.cpu_s["bare"] = sum(v for k, v in cpu.items() if k.startswith("bare "))
    if uplinks > 1:
        result.uplink_cpu = [cpu[f"uplink {n}"] for n in range(uplinks)]
        result.cpu_s["uplink"] = sum(result.uplink_cpu)
    result.samples = samples
    result.steal_peak = steal_peak(samples, t0, t1)
    result.misrouted = sum(
        1 for robot, seen in reader.sites.items() if seen != {robot_site.get(robot, "?").encode()}
    ) + sum(1 for robot in robot_site if robot not in reader.sites)
    for stats in all_stats:
        result.dropped += int(stats.get("intake", {}).get("dropped", 0))
        sender = stats.get("streams", {}).get("durable", {}).get("sender", {})
        if os.environ.get("BENCH_DEBUG"):
            print(
                "edge sender:",
                json.dumps(sender),
                "processor:",
                json.dumps(stats.get("processor")),
                flush=True,
            )
        result.batches += int(sender.get("batches_sent", 0))
        result.batch_records += int(sender.get("records_sent", 0))
        subs = stats.get("subscriptions", {})
        result.gaps += sum(int(s.get("gaps", 0)) for s in subs.values())
        result.missing += sum(int(s.get("missing", 0)) for s in subs.values())
        result.registered.append(len(stats.get("robots", {})))
    return result


def steal_peak(samples: list[Sample], start: float, end: float) -> tuple[float, float] | None:
    """The sampling interval within ``[start, end]`` with the most VM steal: ``(its start from
    ``start`` in s, steal s)``. A stall every process of a run shares shows there, not in one of them."""
    pairs = [(a, b) for a, b in itertools.pairwise(samples) if start <= a.at and b.at <= end]
    if not pairs:
        return None
    a, b = max(pairs, key=lambda p: p[1].steal_s - p[0].steal_s)
    return a.at - start, b.steal_s - a.steal_s


def timeline(window: list[tuple[float, int]], start_ms: float, step_s: int = 5) -> str:
    """Latency p50/p99 (ms) of the records published in each ``step_s`` of the window."""
    steps: dict[int, list[float]] = {}
    for recv, stamp in window:
        steps.setdefault(int((stamp - start_ms) // (1000 * step_s)), []).append(recv * 1000 - stamp)
    return ", ".join(
        f"+{k * step_s}s {statistics.median(v):.0f}/{percentile(v, 0.99):.0f}"
        for k, v in sorted(steps.items())
    )


def worst_second(window: list[tuple[float, int]], start_ms: float) -> tuple[float, float] | None:
    """``(seconds from the window's start, p99 ms)`` of the second whose records fared worst."""
    seconds: dict[int, list[float]] = {}
    for recv, stamp in window:
        seconds.setdefault(int((stamp - start_ms) // 1000), []).append(recv * 1000 - stamp)
    if not seconds:
        return None
    at, lat = max(seconds.items(), key=lambda item: percentile(item[1], 0.99))
    return float(at), percentile(lat, 0.99)


def read_stats(path: Path) -> dict[str, Any]:
    try:
        data: dict[str, Any] = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return data


def main() -> None:
    exit_on_sigterm()
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--shape", action="append", help=f"ROBOTSxTOPICSxHZ (default: {' '.join(DEFAULT_SHAPES)})"
    )
    ap.add_argument("--seconds", type=float, default=30.0, help="how long the robots publish")
    ap.add_argument("--warmup", type=float, default=5.0, help="seconds not counted at the start")
    ap.add_argument("--runs", type=int, default=2, help="runs of each shape (this machine is noisy)")
    ap.add_argument(
        "--warmup-runs",
        type=int,
        default=1,
        help="runs of the first shape before the counted ones, printed but not counted (a broker"
        " just started is slow until its JVM has compiled its hot paths)",
    )
    ap.add_argument(
        "--sites",
        type=int,
        default=1,
        help="split the robots over this many sites (a router and an edge each)",
    )
    ap.add_argument("--uplinks", type=int, default=1, help="uplinks serving the sites")
    ap.add_argument(
        "--coalesce",
        metavar="DURATION",
        help="the edges' intake.coalesce (default: the edge's default; 0s turns it off)",
    )
    ap.add_argument(
        "--busy-coalesce",
        metavar="DURATION",
        help="the edges' intake.busy_coalesce (default: the edge's default; 0s turns it off)",
    )
    ap.add_argument(
        "--robot-tick",
        type=float,
        default=2.0,
        metavar="MS",
        help="each robot process wakes at most once per this many ms (at most half a topic's period)"
        " and publishes what is due then, robot after robot (0: a wake-up per publication; 1,000"
        " robots then cost the machine twice the CPU pacing themselves)",
    )
    ap.add_argument(
        "--bare",
        action="store_true",
        help="beside each edge, a bare Zenoh client receiving the same samples and doing nothing"
        " with them (bench/bare_receiver.py): the receive path's floor, in the same run",
    )
    args = ap.parse_args()
    shapes = [Shape.parse(s) for s in (args.shape or DEFAULT_SHAPES)]
    intake = {
        key: value
        for key, value in (("coalesce", args.coalesce), ("busy_coalesce", args.busy_coalesce))
        if value is not None
    }
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
        plan = [(shapes[0], -1 - n) for n in range(args.warmup_runs)] if shapes else []
        plan += [(shape, run) for shape in shapes for run in range(args.runs)]
        for shape, run in plan:
            result = run_shape(
                work / f"{shape.robots}-{shape.topics}-{shape.hz:g}-{run}",
                shape,
                bootstrap,
                registry,
                args.seconds,
                args.warmup,
                args.sites,
                args.uplinks,
                intake,
                args.bare,
                args.robot_tick / 1000,
            )
            label = f"run {run + 1}" if run >= 0 else "warm-up (not counted)"
            print(f"{label}: {result.line()}", flush=True)


if __name__ == "__main__":
    main()
