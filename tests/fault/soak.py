"""A fleet of robots into an edge whose WAN is cut: memory over time, and every message accounted.

``run_fleet`` starts, as real processes, an edge agent and a fleet of robots
(``bench.fleet_publisher``: each robot its own Zenoh session, real recorded messages) through a
site router whose WAN link is cut from the start; it samples the edge's resident memory after a
warm-up, then stops the robots and accounts for every message: published = lost in transit
(sequence gaps) + dropped at the intake + held in the spool + evicted (``drop_oldest``) + refused
(``block``, ``drop_newest``). ``run_soak`` is the memory soak (a small, full spool); used by
tests/fault/test_memory_soak.py, tests/fault/test_receive_under_load.py and bench/bench_soak.py.
"""

from __future__ import annotations

import subprocess
import sys
import time
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from bench.fleet_publisher import TOPICS
from fleetlink.localstack.relay import TcpRelay
from fleetlink.localstack.zenoh_router import ZenohRouter
from tests.fault.e2e_processes import Process
from tests.fault.stats_file import Settled, read_stats
from tests.helpers import wait_until
from tests.paths import ROOT


@dataclass
class Soak:
    policy: str
    published: int = 0
    rss_mb: list[float] = field(default_factory=list)
    """Resident memory of the edge, sampled every half second after the warm-up."""
    stats: dict[str, Any] = field(default_factory=dict)
    registrations: int = 0

    def count(self, *path: str) -> int:
        value: Any = self.stats
        for key in path:
            value = value.get(key, {}) if isinstance(value, dict) else {}
        return int(value) if isinstance(value, int) else 0

    @property
    def missing(self) -> int:
        return sum(int(s.get("missing", 0)) for s in self.stats.get("subscriptions", {}).values())

    def accounted(self) -> dict[str, int]:
        """Where every published message went (each counted once)."""
        buffer = ("streams", "durable", "buffer")
        return {
            "lost in transit (sequence gaps)": self.missing,
            "dropped at the intake": self.count("intake", "dropped"),
            "held in the spool": self.count(*buffer, "depth"),
            "evicted (drop_oldest)": self.count(*buffer, "dropped_oldest"),
            "refused by the spool (block)": self.count("processor", "spool_refused"),
            "dropped by the spool (drop_newest)": self.count("processor", "spool_dropped"),
        }

    def growth(self) -> float:
        """The largest resident memory over the first one, after the warm-up."""
        return max(self.rss_mb) / self.rss_mb[0]

    def summary(self) -> str:
        return (
            f"{self.policy}: published {self.published}, "
            + ", ".join(f"{k} {v}" for k, v in self.accounted().items())
            + f"; edge RSS {self.rss_mb[0]:.0f} -> {max(self.rss_mb):.0f} MB (x{self.growth():.3f})"
        )


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


def run_soak(
    tmp: Path,
    policy: str,
    *,
    robots: int = 10,
    hz: float = 500.0,
    seconds: float = 20.0,
    warmup_s: float = 6.0,
) -> Soak:
    """Robots publish ``robots * hz`` Imu messages/s for ``seconds`` into a 4 MiB spool with full
    policy ``policy``; memory is sampled after ``warmup_s`` (the spool fills in two or three)."""
    spool = {"segment_bytes": "1MiB", "max_bytes": "4MiB", "policy": policy, "block_timeout": "500ms"}
    return run_fleet(
        tmp, policy, robots=robots, topics=1, hz=hz, seconds=seconds, warmup_s=warmup_s, spool=spool
    )


def run_fleet(
    tmp: Path,
    name: str,
    *,
    robots: int,
    topics: int,
    hz: float,
    seconds: float,
    warmup_s: float,
    spool: dict[str, Any],
    block: bool = False,
    intake: dict[str, Any] | None = None,
) -> Soak:
    """``robots`` robots publish ``topics`` topics each at ``hz`` for ``seconds`` (``block``:
    reliable, blocking publishers) into an edge with the ``spool`` (and ``intake``) settings,
    the WAN cut."""
    result = Soak(name)
    with ExitStack() as stack:
        cloud = stack.enter_context(ZenohRouter())
        wan = stack.enter_context(TcpRelay(cloud.port))
        wan.set_mode("blackhole")  # the WAN is cut from the start: nothing leaves the spool
        site = stack.enter_context(ZenohRouter(connect=(wan.endpoint,)))
        stats_file = tmp / "edge-stats.json"
        config = {
            "site": "soak",
            "edge_id": "edge-1",
            "zenoh": {"mode": "client", "connect": [site.endpoint]},
            "robot_types": {
                "bench": {
                    "match": "/r*",
                    "mappings": [
                        {
                            "name": topic,
                            "from": f"/{{robot}}/{topic}",
                            "to": f"soak.{topic}",
                            "type": typename,
                        }
                        for topic, typename, _bag_topic, _bag in TOPICS[:topics]
                    ],
                }
            },
            "spool": {"dir": str(tmp / "spool"), **spool},
            "wan": {"ack_timeout": "2s"},
        }
        if intake:
            config["intake"] = intake
        edge_yaml = tmp / "edge.yaml"
        edge_yaml.write_text(yaml.safe_dump(config))
        edge = Process(
            "edge",
            [
                "edge",
                "run",
                "-c",
                str(edge_yaml),
                "--stats-file",
                str(stats_file),
                "--stats-interval",
                "0.25",
            ],
            tmp / "edge.log",
        ).start()
        stack.callback(edge.terminate, 10)
        argv = [sys.executable, "-m", "bench.fleet_publisher", "--connect", site.endpoint]
        argv += ["--robots", str(robots), "--topics", str(topics), "--hz", str(hz), "--seconds", str(seconds)]
        argv += ["--wait-subscribed", "30"]
        pub = subprocess.Popen(
            [*argv, *(["--block"] if block else [])],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            cwd=ROOT,
        )
        stack.callback(pub.kill)
        assert pub.stdout is not None
        assert pub.stdin is not None
        assert pub.stdout.readline().strip() == "ready", "the robots did not start"

        def stats() -> dict[str, Any]:
            return read_stats(stats_file)[1]

        def took_every_robot() -> bool:
            if edge.proc is None or edge.proc.poll() is not None:
                raise AssertionError("the edge ended before it took the robots")
            data = stats()
            return (
                len(data.get("subscriptions", {})) >= robots * topics
                and len(data.get("robots", {})) >= robots
            )

        try:
            wait_until(took_every_robot, 60, interval=0.05, message=f"the edge takes the {robots} robots")
        except AssertionError as exc:
            raise AssertionError(f"{exc}\n{edge.tail()}") from None
        result.registrations = robots
        began = time.monotonic()
        pub.stdin.write("go\n")
        pub.stdin.flush()
        time.sleep(warmup_s)  # ok-sleep: the warm-up the soak leaves uncounted
        assert edge.proc is not None
        while time.monotonic() - began < seconds:
            result.rss_mb.append(_rss_mb(edge.proc.pid))
            time.sleep(0.5)  # ok-sleep: the RSS sampling interval over the soak
        done = pub.stdout.readline().split()
        assert done[:1] == ["done"], f"the robots did not publish: {' '.join(done)}"
        result.published = int(done[1])

        def processed(data: dict[str, Any]) -> bool:
            """Every sample arrived or is a gap (each publisher's last one is never dropped on the
            way: it comes, and shows any loss before it), and what the edge took it processed."""
            intake, processor = data.get("intake", {}), data.get("processor", {})
            missing = sum(int(s.get("missing", 0)) for s in data.get("subscriptions", {}).values())
            return bool(
                int(intake.get("offered", 0)) + missing >= result.published
                and intake.get("queued") == 0
                and intake.get("taken") == processor.get("samples")
            )

        settled = Settled(stats_file, lambda data: data.get("intake", {}).get("offered"), processed)
        try:
            wait_until(settled.check, 30, interval=0.05, message="the edge took and processed every sample")
        except AssertionError as exc:
            raise AssertionError(f"{exc}\n{_progress(stats(), result.published)}\n{edge.tail()}") from None
        result.stats = settled.stats
        pub.stdin.write("bye\n")
        pub.stdin.flush()
    return result


def _progress(data: dict[str, Any], published: int) -> str:
    """What ``processed`` judges, from the edge's last stats: to tell which part never held."""
    intake, processor = data.get("intake", {}), data.get("processor", {})
    subscriptions = data.get("subscriptions", {}).values()
    missing = sum(int(s.get("missing", 0)) for s in subscriptions)
    received = sum(int(s.get("received", 0)) for s in subscriptions)
    return (
        f"published {published}; intake offered {intake.get('offered')} + missing {missing} "
        f"(received {received}, gaps {sum(int(s.get('gaps', 0)) for s in subscriptions)}); "
        f"intake queued {intake.get('queued')}, dropped {intake.get('dropped')}; "
        f"taken {intake.get('taken')} vs processed {processor.get('samples')}, "
        f"processor errors {processor.get('errors')}"
    )
