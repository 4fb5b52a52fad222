"""Measure the app's share of the fault-to-LED time: ``python -m fleetlink.examples.fault_detection.latency``.

A simulated robot produces its three sensor topics at ``--rate`` Hz each, stamped with the wall
clock as a live robot does. Each run switches it to "picked up" and waits for the red command,
then puts it down and waits for the green one. For every command it reports

* ``total``: from the stamp of the first failing (healed) record to the command being
  readable in Kafka, on the wall clock;
* ``window``: the part the rule itself imposes (command stamp - that first stamp): the window
  length, less the gap since the last record before the change (the window must only outgrow
  that record: about one sensor period, more if the robot was held up);
* ``app``: the rest (command arrival - command stamp): Kafka round trips and processing;
* ``gap``: from the last record before the change to the first after it;
* ``due``: from the first record after the change to the first record stamped a whole window
  after the last one before it: the earliest record that can complete an all-failing (healed)
  window. ``window + gap`` exceeds the window length, and ``window`` is at most ``due``.

It measures Kafka → app → Kafka only; the edge, uplink and repeater legs are not included.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fleetlink.examples.fault_detection.settings import FaultDetectionSettings, Topics, parse_duration_ms

PKG = "irobot_create_msgs/msg/"
SENSOR_TYPES = {"ir": "IrIntensityVector", "hazard": "HazardDetectionVector", "kidnap": "KidnapStatus"}
ROBOT = "tb4_lat"
WHEEL_DROP, BUMP = 4, 1


def now_ms() -> int:
    """The wall clock in milliseconds since the epoch."""
    return time.time_ns() // 1_000_000


def datum(sensor: str, ts: int, failing: bool) -> dict[str, Any]:
    """One record of ``sensor`` stamped ``ts`` (ms) that says failure (``failing``) or healthy."""
    header = {"stamp": {"sec": ts // 1000, "nanosec": (ts % 1000) * 1_000_000}, "frame_id": "base_link"}
    if sensor == "ir":
        value = 3800 if failing else 20
        return {"header": header, "readings": [{"header": header, "value": value} for _ in range(7)]}
    if sensor == "kidnap":
        return {"header": header, "is_kidnapped": failing}
    kinds = [WHEEL_DROP] if failing else [BUMP]
    return {"header": header, "detections": [{"header": header, "type": k} for k in kinds]}


@dataclass
class Arrival:
    """A light-ring command read back from Kafka: the state it sets, its stamp and when it arrived (ms)."""

    state: str
    stamp_ms: int
    arrived_ms: int


@dataclass(frozen=True)
class Measurement:
    """The latencies of one command in milliseconds: total, the part the window imposes, the app's part."""

    state: str
    total_ms: int
    window_ms: int
    app_ms: int
    gap_ms: int
    due_ms: int


@dataclass
class Robot:
    """Publishes the three sensor topics until stopped; ``failing`` flips what they say.

    ``changed_at`` is the stamp of the first record sent after ``failing`` last changed,
    ``before_change`` that of the last one before it, ``stamps`` those of every record since.
    """

    producer: Any
    topics: dict[str, str]
    frames: dict[str, tuple[bytes, Any]]  # sensor -> (Confluent prefix, codec)
    period_s: float
    failing: bool = False
    changed_at: int | None = None
    before_change: int | None = None
    last_stamp: int | None = None
    stamps: list[int] = field(default_factory=list)
    stop: threading.Event = field(default_factory=threading.Event)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def flip(self, failing: bool) -> None:
        """Make the next records say failure (``failing``) or healthy, and restart ``changed_at``."""
        with self.lock:
            self.changed_at = None
            self.before_change = self.last_stamp
            self.stamps = []
            self.failing = failing

    def change(self) -> tuple[int, int, list[int]] | None:
        """Stamps: the first record after the last change, the last one before it, all since."""
        with self.lock:
            if self.changed_at is None or self.before_change is None:
                return None
            return self.changed_at, self.before_change, list(self.stamps)

    def loop(self) -> None:
        """Produce one record per sensor every ``period_s`` until ``stop`` is set, then flush."""
        while not self.stop.wait(self.period_s):
            with self.lock:
                ts, failing = now_ms(), self.failing
                if self.changed_at is None:
                    self.changed_at = ts
                self.last_stamp = ts
                self.stamps.append(ts)
            for sensor, (prefix, codec) in self.frames.items():
                body = codec.encode_datum(datum(sensor, ts, failing))
                self.producer.produce(
                    self.topics[sensor], key=ROBOT.encode(), value=prefix + body, timestamp=ts
                )
            self.producer.poll(0)
        self.producer.flush(10)


def watch_commands(bootstrap: str, topic: str, arrivals: list[Arrival], stop: threading.Event) -> None:
    """Append an ``Arrival`` for each command on ``topic`` (from its start) until ``stop`` is set."""
    from confluent_kafka import Consumer, TopicPartition

    consumer = Consumer({"bootstrap.servers": bootstrap, "group.id": f"latency-{uuid.uuid4()}"})
    consumer.assign([TopicPartition(topic, 0, 0)])
    try:
        while not stop.is_set():
            msg = consumer.poll(0.05)
            if msg is None or msg.error():
                continue
            arrived = now_ms()
            state = dict(msg.headers() or [])["fleetlink-command-id"].decode().split("-")[-2]
            arrivals.append(Arrival(state, msg.timestamp()[1], arrived))
    finally:
        consumer.close()


def wait_until_consuming(bootstrap: str, group: str, topic: str, timeout_s: float) -> None:
    """Until the app's group has committed an offset on ``topic``: it is reading live data."""
    from confluent_kafka import Consumer, KafkaException, TopicPartition

    consumer = Consumer({"bootstrap.servers": bootstrap, "group.id": group, "enable.auto.commit": False})
    deadline = time.monotonic() + timeout_s
    try:
        while time.monotonic() < deadline:
            try:
                [committed] = consumer.committed([TopicPartition(topic, 0)], timeout=5)
            except KafkaException:
                committed = None
            if committed is not None and committed.offset > 0:
                return
            time.sleep(0.1)
    finally:
        consumer.close()
    raise TimeoutError(f"the app (group {group}) did not start consuming {topic} within {timeout_s} s")


def wait_for(arrivals: list[Arrival], count: int, timeout_s: float) -> Arrival:
    """The ``count``-th arrival, once there; raises ``TimeoutError`` after ``timeout_s`` seconds."""
    deadline = time.monotonic() + timeout_s
    while len(arrivals) < count:
        if time.monotonic() > deadline:
            raise TimeoutError(f"no command #{count} within {timeout_s} s")
        time.sleep(0.005)
    return arrivals[count - 1]


def measure(args: argparse.Namespace) -> list[Measurement]:
    """One measurement per command."""
    from confluent_kafka import Producer
    from confluent_kafka.admin import AdminClient, NewTopic
    from confluent_kafka.schema_registry import Schema, SchemaRegistryClient

    from fleetlink.examples.fault_detection.app import run
    from fleetlink.schemas.codec import get_codec
    from fleetlink.schemas.typestore import load_typestore

    run_id = uuid.uuid4().hex[:8]
    topics = Topics(
        ir_intensity=f"latency.{run_id}.ir_intensity",
        hazard_detection=f"latency.{run_id}.hazard_detection",
        kidnap_status=f"latency.{run_id}.kidnap_status",
        commands=f"latency.{run_id}.commands.lightring",
    )
    names = {"ir": topics.ir_intensity, "hazard": topics.hazard_detection, "kidnap": topics.kidnap_status}
    admin = AdminClient({"bootstrap.servers": args.bootstrap})
    new = [NewTopic(n, num_partitions=1, replication_factor=1) for n in [*names.values(), topics.commands]]
    for future in admin.create_topics(new).values():
        future.result(timeout=30)
    ts = load_typestore(args.distro, [Path(p) for p in args.msg_path])
    registry = SchemaRegistryClient({"url": args.registry})
    frames = {}
    for sensor, typename in SENSOR_TYPES.items():
        codec = get_codec(ts, PKG + typename, args.distro)
        schema_id = registry.register_schema(
            f"{names[sensor]}-value", Schema(json.dumps(codec.schema), "AVRO")
        )
        frames[sensor] = (b"\x00" + schema_id.to_bytes(4, "big"), codec)

    rows: list[Measurement] = []
    arrivals: list[Arrival] = []
    stop = threading.Event()
    with tempfile.TemporaryDirectory(prefix="fd-latency-") as state_dir:
        settings = FaultDetectionSettings(
            bootstrap=args.bootstrap,
            registry_url=args.registry,
            window=args.window / 1000,
            group=f"latency-{run_id}",
            state_dir=Path(state_dir),
            offset_reset="earliest",
            msg_paths=tuple(Path(p) for p in args.msg_path),
            distro=args.distro,
            topics=topics,
        )
        producer = Producer({"bootstrap.servers": args.bootstrap, "linger.ms": 0})
        robot = Robot(producer, names, frames, 1.0 / args.rate)
        threads = [
            threading.Thread(target=run, args=(settings, stop), name="app"),
            threading.Thread(target=robot.loop, name="robot"),
            threading.Thread(target=watch_commands, args=(args.bootstrap, topics.commands, arrivals, stop)),
        ]
        for thread in threads:
            thread.start()
        try:
            wait_until_consuming(args.bootstrap, settings.group, topics.ir_intensity, timeout_s=60)
            for _ in range(args.runs):
                for failing in (True, False):
                    robot.flip(failing)
                    arrival = wait_for(arrivals, len(rows) + 1, timeout_s=args.window / 1000 + 30)
                    change = robot.change()
                    if change is None:  # the command came before any record of the change: impossible
                        raise RuntimeError(f"command {arrival} before the robot reported the change")
                    start, before, stamps = change
                    due = next((s for s in stamps if s - before > args.window), arrival.stamp_ms)
                    row = Measurement(
                        arrival.state, arrival.arrived_ms - start, arrival.stamp_ms - start,
                        arrival.arrived_ms - arrival.stamp_ms, start - before, due - start,
                    )  # fmt: skip
                    rows.append(row)
                    print(f"{row.state:8} total {row.total_ms:5d} ms  window {row.window_ms:5d} ms  "
                          f"app {row.app_ms:4d} ms  gap {row.gap_ms:4d} ms  due {row.due_ms:5d} ms",
                          flush=True)  # fmt: skip
        finally:
            robot.stop.set()
            stop.set()
            for thread in threads:
                thread.join(30)
    return rows


def summary(rows: Sequence[Measurement]) -> str:
    """The p50, p90 and maximum of the total, window and app latencies, one line each."""

    def pct(values: list[int], q: float) -> float:
        ordered = sorted(values)
        return float(ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))])

    lines = []
    for label in ("total", "window", "app"):
        values = [getattr(row, f"{label}_ms") for row in rows]
        lines.append(
            f"{label:7} p50 {statistics.median(values):7.1f} ms   p90 {pct(values, 0.9):7.1f} ms   "
            f"max {max(values):5d} ms   (n={len(values)})"
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Measure the fault-detection app's latency over ``--runs`` fault/heal cycles and print a summary."""
    parser = argparse.ArgumentParser(
        prog="python -m fleetlink.examples.fault_detection.latency", description=__doc__
    )
    parser.add_argument("--bootstrap", required=True)
    parser.add_argument("--registry", required=True)
    parser.add_argument(
        "--msg-path", action="append", required=True, help="irobot_create_msgs package folder"
    )
    parser.add_argument("--distro", default="jazzy", choices=("humble", "jazzy", "kilted"))
    parser.add_argument("--window", type=parse_duration_ms, default=2000, help="window (default: 2s)")
    parser.add_argument(
        "--rate", type=float, default=10.0, help="messages per second per sensor (default: 10)"
    )
    parser.add_argument("--runs", type=int, default=10, help="fault/heal cycles (default: 10)")
    args = parser.parse_args(argv)
    rows = measure(args)
    print(summary(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
