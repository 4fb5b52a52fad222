"""The fault-test bed: edge and uplink as real processes, a WAN relay, a counting generator.

::

    generator (robot tb4_01, std_msgs/String "0", "1", ...) -> site router -> edge process
      -> site router -> TcpRelay (the WAN: pass / blackhole) -> cloud router -> uplink process -> Kafka

Processes are ``python -m fleetlink edge run`` / ``uplink run`` started and stopped by PID
(SIGTERM, or SIGKILL for crashes). The edge writes its counters to a JSON stats file the test
polls. After the fault the test reads the Kafka topic from the beginning and counts, Jepsen
style: ``lost``, ``duplicated``, ``unexpected`` and per-key order of first occurrences.
"""

from __future__ import annotations

import itertools
import json
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit, urlunsplit

import yaml
from confluent_kafka import Consumer, Message, TopicPartition

from fleetlink.localstack.relay import TcpRelay
from fleetlink.localstack.zenoh_router import ZenohRouter
from fleetlink.roswire import cdr
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.publisher import RosPublisher
from fleetlink.schemas.typestore import load_typestore
from tests.fault.stats_file import read_stats
from tests.helpers import wait_until, zenoh_peer_config
from tests.integration.e2e_stack import TopicReader

ROOT = Path(__file__).resolve().parents[2]
STRING = "std_msgs/msg/String"


@dataclass(frozen=True)
class WanProfile:
    """The WAN settings of the edges under test (``None``: the edge's default)."""

    name: str
    batch_max_records: int | None
    max_in_flight: int | None
    delivery: str = "at_least_once"
    """The edge's ``spool.delivery``."""

    @property
    def batch(self) -> int:
        """Records per batch at most (the edge's default is 2,000)."""
        return self.batch_max_records or 2000

    @property
    def window(self) -> int:
        """Records one fault may make Kafka hold twice: those in flight, none exactly once."""
        if self.delivery == "exactly_once":
            return 0
        return self.batch * (self.max_in_flight or 4)

    def settings(self) -> dict[str, int]:
        out = {"batch_max_records": self.batch_max_records, "max_in_flight": self.max_in_flight}
        return {k: v for k, v in out.items() if v is not None}


PROFILES = (WanProfile("1x100", 100, 1), WanProfile("defaults", None, None))
"""Every end-to-end fault test runs with one small batch in flight and with the defaults."""
EXACTLY_ONCE = WanProfile("exactly_once", None, None, "exactly_once")
"""The defaults with ``spool.delivery: exactly_once``: the faults that can duplicate a batch
(a lost ack, a killed process, a cut or flapping WAN) must duplicate nothing."""
WITH_EXACTLY_ONCE = (*PROFILES, EXACTLY_ONCE)
PROFILE = PROFILES[0]
"""The profile of the test running (``tests/fault/conftest.py: wan_profile`` sets it)."""


class Process:
    """One fleetlink process; its output goes to a log file shown when a test fails."""

    def __init__(self, name: str, argv: list[str], log: Path) -> None:
        self.name = name
        self.argv = argv
        self.log = log
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self, env: dict[str, str] | None = None) -> Process:
        """Start it (``env``: the whole environment, else this process's)."""
        with self.log.open("ab") as out:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "fleetlink", "-v", *self.argv],
                cwd=ROOT,
                stdout=out,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                env=env,
            )
        return self

    def kill(self) -> None:
        """SIGKILL: no clean shutdown, nothing flushed."""
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait(10)
            self.proc = None

    def pause(self) -> None:
        """SIGSTOP: every thread of the process stops (a stalled host, not a crash)."""
        if self.proc is not None:
            self.proc.send_signal(signal.SIGSTOP)

    def resume(self) -> None:
        if self.proc is not None:
            self.proc.send_signal(signal.SIGCONT)

    def terminate(self, timeout: float) -> tuple[int | None, float]:
        """SIGTERM; returns (exit code, seconds it took), code None if it did not exit in time."""
        proc = self.proc
        if proc is None:
            return None, 0.0
        began = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        try:
            code = proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)
            self.proc = None
            return None, time.monotonic() - began
        self.proc = None
        return code, time.monotonic() - began

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def tail(self, lines: int = 40) -> str:
        try:
            return "\n".join(self.log.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return ""

    def log_lines(self, needle: str) -> int:
        try:
            return sum(needle in line for line in self.log.read_text(errors="replace").splitlines())
        except OSError:
            return 0


@dataclass
class Bed:
    """Everything one fault test runs; built by ``bed()``."""

    tmp: Path
    bootstrap: str
    registry_url: str
    cloud: ZenohRouter
    relay: TcpRelay
    site: ZenohRouter
    site_name: str
    topic: str
    dead_letter: str
    edge_yaml: Path
    uplink_yaml: Path
    stats_file: Path
    registry_relay: TcpRelay | None = None
    """Between the uplink and the schema registry, when the bed was asked for one."""
    edge: Process | None = None
    uplink: Process | None = None
    processes: list[Process] = field(default_factory=list)

    def start_edge(self) -> Process:
        """Start an edge. A previous edge's stats file goes first: a killed edge's last write would
        otherwise answer for the new one until it writes its own."""
        n = sum(p.name == "edge" for p in self.processes)
        self.stats_file.unlink(missing_ok=True)
        self.edge = Process(
            "edge",
            [
                "edge",
                "run",
                "-c",
                str(self.edge_yaml),
                "--stats-file",
                str(self.stats_file),
                "--stats-interval",
                "0.2",
                "--stop-timeout",
                "5",
            ],
            self.tmp / f"edge-{n}.log",
        ).start()
        self.processes.append(self.edge)
        return self.edge

    def start_uplink(self) -> Process:
        """Start the uplink and wait until it serves batches (it first reads the registrations
        topic to its end: an edge started earlier would see its first batches go unanswered)."""
        n = sum(p.name == "uplink" for p in self.processes)
        uplink = self.uplink = Process(
            "uplink", ["uplink", "run", "-c", str(self.uplink_yaml)], self.tmp / f"uplink-{n}.log"
        ).start()
        self.processes.append(uplink)
        self.wait(lambda: uplink.log_lines("uplink running") > 0, 30, "the uplink serves batches")
        return uplink

    def stats(self) -> dict[str, Any]:
        return read_stats(self.stats_file)[1]

    def durable(self) -> dict[str, Any]:
        stream: dict[str, Any] = self.stats().get("streams", {}).get("durable", {})
        return stream

    def assert_memory_bounded(self) -> None:
        """The edge's resident memory is under the bound its configuration implies (docs/edge.md):
        whatever the fault, the backlog waits in the spool, not in the process."""
        memory = self.stats().get("memory", {})
        rss, bound = memory.get("rss_bytes", 0), memory.get("bound_bytes", 0)
        assert rss > 0
        assert bound > 0
        assert rss <= bound, f"the edge holds {rss >> 20} MiB, over its bound of {bound >> 20} MiB"

    def wait_drained(self, records: int, timeout: float) -> None:
        """Every one of ``records`` samples spooled, and the spool empty (all acknowledged)."""

        def drained() -> bool:
            stats = self.stats()
            buffer = self.durable().get("buffer", {})
            return bool(
                stats.get("processor", {}).get("samples", 0) >= records
                and buffer.get("depth") == 0
                and stats.get("running")
            )

        self.wait(drained, timeout, f"{records} records spooled and acknowledged")

    def wait(self, condition: Any, timeout: float, what: str) -> None:
        try:
            wait_until(condition, timeout, interval=0.1, message=what)
        except AssertionError as exc:
            stats = json.dumps(self.stats())[:3000]
            raise AssertionError(f"{exc}\nedge stats: {stats}\n{self.logs()}") from None

    def logs(self) -> str:
        """The tail of each process's log (those of processes started again included)."""
        return "\n".join(f"--- {p.log.name}\n{p.tail()}" for p in self.processes)

    def stop_all(self) -> None:
        for process in self.processes:
            if process.alive():
                process.terminate(10)


def _write_yaml(path: Path, data: dict[str, Any]) -> Path:
    path.write_text(yaml.safe_dump(data))
    return path


@contextmanager
def bed(
    tmp: Path, bootstrap: str, registry_url: str, *, ack_timeout: str = "10s", registry_relay: bool = False
) -> Iterator[Bed]:
    """Routers and the relay in this process; config files for the edge and uplink processes.
    ``registry_relay``: the uplink reaches the registry through a relay too (``Bed.registry_relay``)."""
    run = uuid.uuid4().hex[:8]
    with ExitStack() as stack:
        to_registry = None
        uplink_registry = registry_url
        if registry_relay:
            url = urlsplit(registry_url)
            assert url.port is not None, registry_url
            to_registry = stack.enter_context(TcpRelay(url.port))
            uplink_registry = urlunsplit(url._replace(netloc=f"127.0.0.1:{to_registry.port}"))
        cloud = stack.enter_context(ZenohRouter())
        relay = stack.enter_context(TcpRelay(cloud.port))
        site = stack.enter_context(ZenohRouter(connect=(relay.endpoint,)))
        site_name, topic, dead_letter = f"fault-{run}", f"fault.chat.{run}", f"fault.dead-letter.{run}"
        edge_yaml = _write_yaml(
            tmp / "edge.yaml",
            {
                "site": site_name,
                "edge_id": "edge-1",
                "zenoh": {"mode": "client", "connect": [site.endpoint]},
                "robot_types": {
                    "tb4": {
                        "match": "/tb4_*",
                        "mappings": [
                            {"name": "chat", "from": "/{robot}/chatter", "to": topic, "type": STRING}
                        ],
                    }
                },
                "spool": {
                    "dir": str(tmp / "spool"),
                    "delivery": PROFILE.delivery,
                    "segment_bytes": "1MiB",
                    "max_bytes": "64MiB",
                    "fsync": "interval",
                    "fsync_interval": "50ms",
                },
                "registration": {"grace_period": "30s"},
                "wan": {
                    **PROFILE.settings(),
                    "linger": "10ms",
                    "ack_timeout": ack_timeout,
                    "retry_backoff_min": "100ms",
                    "retry_backoff_max": "1s",
                },
                "topics": {"dead_letter": dead_letter, "registrations": f"fault.robots.{run}"},
            },
        )
        uplink_yaml = _write_yaml(
            tmp / "uplink.yaml",
            {
                "kafka": {"bootstrap_servers": bootstrap},
                "registry": {"url": uplink_registry},
                "zenoh": {"mode": "client", "connect": [cloud.endpoint]},
                "topics": {"dead_letter": dead_letter, "registrations": f"fault.robots.{run}"},
            },
        )
        test_bed = Bed(
            tmp,
            bootstrap,
            registry_url,
            cloud,
            relay,
            site,
            site_name,
            topic,
            dead_letter,
            edge_yaml,
            uplink_yaml,
            tmp / "edge-stats.json",
            to_registry,
        )
        try:
            yield test_bed
        finally:
            test_bed.stop_all()


@contextmanager
def streaming(
    tmp: Path, bootstrap: str, registry_url: str, *, ack_timeout: str = "10s", rate: float = 400.0
) -> Iterator[tuple[Bed, Generator]]:
    """A bed with the uplink and the edge started and the generator publishing."""
    with bed(tmp, bootstrap, registry_url, ack_timeout=ack_timeout) as b:
        b.start_uplink()
        b.start_edge()
        gen = Generator(b.site.endpoint, rate)
        try:
            gen.wait_subscribed()
            gen.start()
            yield b, gen
        finally:
            gen.close()


def tally(reader: TopicReader, b: Bed, sent: int, what: str = "") -> Count:
    """Count what reached the bed's topic (and print it, with ``what`` happened)."""
    result = count(reader, read_all(reader, b.topic, sent), sent)
    print(f"\n[{b.site_name}] {sent} sent{what}: {result}")
    if result.out_of_order or result.unexpected:
        print(b.logs())
    return result


def generate(b: Bed, gen: Generator, records: int, timeout: float = 30.0) -> None:
    """Let the generator publish ``records`` more."""
    target = gen.sent + records
    b.wait(lambda: gen.sent >= target, timeout, f"{records} more records published")


def spool_depth(b: Bed, at_least: int, what: str) -> int:
    """Wait until the edge's spool holds ``at_least`` records (its stats file lags what the
    generator published by a write interval and the edge's own pace); returns the depth."""
    depth = 0

    def deep() -> bool:
        nonlocal depth
        depth = int(b.durable().get("buffer", {}).get("depth", 0))
        return depth >= at_least

    b.wait(deep, 15, f"{what} ({at_least} records in the spool)")
    return depth


class Generator:
    """Robot ``tb4_01`` publishing ``"0"``, ``"1"``, ... on ``/tb4_01/chatter`` at ``rate`` Hz."""

    def __init__(self, router: str, rate: float = 400.0) -> None:
        self.rate = rate
        self.node = RosNode(
            "gen", "/tb4_01", config=zenoh_peer_config(router), typestore=load_typestore("jazzy")
        ).start()
        self.publisher: RosPublisher = self.node.create_publisher(
            "/tb4_01/chatter", STRING, congestion="block"
        )
        self.sent = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def wait_subscribed(self, timeout: float = 30.0) -> None:
        wait_until(self.publisher.has_subscribers, timeout, message="the edge subscribed to the generator")

    def wait_unsubscribed(self, timeout: float = 30.0) -> None:
        """Until no subscriber matches: after a ``kill -9`` the router drops the dead edge's
        subscription only when it sees the connection close, and until then a match would
        not mean that the next edge listens."""
        wait_until(
            lambda: not self.publisher.has_subscribers(), timeout, message="the router dropped the edge"
        )

    def start(self) -> Generator:
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def _run(self) -> None:
        period = 1.0 / self.rate
        next_at = time.monotonic()
        while not self._stop.is_set():
            self.publisher.publish_cdr(cdr.encode_string(str(self.sent)))
            self.sent += 1
            next_at += period
            delay = next_at - time.monotonic()
            if delay > 0 and self._stop.wait(delay):
                return

    def pause(self) -> int:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)
            self._thread = None
        return self.sent

    def close(self) -> None:
        self.pause()
        self.node.stop()


@dataclass(frozen=True)
class Count:
    """Jepsen-style accounting of what reached Kafka."""

    lost: list[int]
    duplicated: int
    unexpected: int
    out_of_order: int
    inversions: tuple[tuple[int, int, int], ...] = ()
    """``(position, value before, value)`` of the first few values that came after a larger one."""

    def __str__(self) -> str:
        head = self.lost[:10]
        where = f" at (position, before, value) {list(self.inversions)}" if self.inversions else ""
        return (
            f"lost {len(self.lost)} {head}, duplicated {self.duplicated}, unexpected {self.unexpected}, "
            f"out of order {self.out_of_order}{where}"
        )


def count(reader: TopicReader, msgs: list[Message], sent: int) -> Count:
    values: list[int] = []
    unexpected = 0
    for msg in msgs:
        try:
            values.append(int(reader.value(msg)["data"]))
        except (ValueError, KeyError, TypeError):
            unexpected += 1
    seen: set[int] = set()
    firsts: list[int] = []
    for v in values:
        if v not in seen:
            seen.add(v)
            firsts.append(v)
    inversions = [(i + 1, a, b) for i, (a, b) in enumerate(itertools.pairwise(firsts)) if b < a]
    out_of_order = len(inversions)
    unexpected += sum(1 for v in seen if not 0 <= v < sent)
    return Count(
        lost=sorted(set(range(sent)) - seen),
        duplicated=len(values) - len(seen),
        unexpected=unexpected,
        out_of_order=out_of_order,
        inversions=tuple(inversions[:10]),
    )


def read_to_end(reader: TopicReader, topic: str, timeout: float = 30.0) -> list[Message]:
    """Every record on the topic now, up to its high watermark: for a test that lost records on
    purpose, once the edge's spool is drained (everything acknowledged is in Kafka), rather than
    waiting out ``read_all``'s deadline for values that will never come."""
    probe = Consumer({"bootstrap.servers": reader.bootstrap, "group.id": f"e2e-{uuid.uuid4().hex}"})
    try:
        _low, high = probe.get_watermark_offsets(TopicPartition(topic, 0), timeout=10)
    finally:
        probe.close()
    return reader.consume(topic, 0, lambda msgs: len(msgs) >= high, timeout)


def read_all(reader: TopicReader, topic: str, sent: int, timeout: float = 30.0) -> list[Message]:
    """Everything on the topic once at least ``sent`` distinct values arrived (or, past the
    deadline, everything up to its end: some were lost, and the count shows which)."""

    def complete(msgs: list[Message]) -> bool:
        return len({m.value() for m in msgs}) >= sent

    try:
        return reader.read_until(topic, complete, timeout, what=f"{sent} distinct records on {topic}")
    except AssertionError:
        return read_to_end(reader, topic)
