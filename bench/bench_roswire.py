"""Benchmark: sensor_msgs/Imu through one zenoh router, roswire subscriber vs a raw zenoh subscriber.

Processes (all on loopback, every session in client mode so every sample crosses the router):

* this process hosts the router and orchestrates;
* one publisher process: a roswire ``RosPublisher`` (rmw_zenoh key, token, 33-byte attachment),
  publishing pre-serialized Imu CDR (324 bytes);
* two subscriber processes running at the same time on the same samples:
  ``roswire``: ``RosSubscriber(decode=True)``: key parsed, attachment parsed, sequence tracked,
  CDR decoded into an Imu object by rosbags; latency taken after decoding;
  ``raw``: a plain ``session.declare_subscriber`` callback that only reads the 8-byte source
  timestamp out of the attachment.

Phase 1 (throughput), once per subscriber kind, on a topic only that subscriber listens to:
the publisher puts N samples as fast as it can with congestion control BLOCK, so the slowest hop
(the receiving callback) sets the pace and nothing is dropped; the subscriber reports samples/s
between its first and last sample. Phase 2 (latency), both subscribers on one topic at once:
the publisher puts at a fixed rate with rmw's default QoS (reliable, congestion DROP); each
subscriber reports publish->receive latency p50/p99 (publisher's ``time.time_ns()`` in the
attachment to the receiver's clock after decoding, same host).

    .venv/bin/python bench/bench_roswire.py [--count 100000] [--rate 1000] [--seconds 5] [--json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

IMU = "sensor_msgs/msg/Imu"
LATENCY_TOPIC = "/bench_bot/imu_both"
DOMAIN = 77


def client_config(endpoint: str) -> Any:
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


def imu_payload() -> bytes:
    from fleetlink.schemas.typestore import load_typestore

    ts = load_typestore("jazzy")
    t = ts.types
    import numpy as np

    msg = t[IMU](
        header=t["std_msgs/msg/Header"](
            stamp=t["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="imu_link"
        ),
        orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=np.zeros(9),
        angular_velocity=t["geometry_msgs/msg/Vector3"](x=0.1, y=0.2, z=0.3),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=9.81),
        linear_acceleration_covariance=np.zeros(9),
    )
    return bytes(ts.serialize_cdr(msg, IMU))


# --- roles (run in child processes) ---------------------------------------------------------


def run_publisher(endpoint: str, topic: str, mode: str, count: int, rate: float, seconds: float) -> None:
    from fleetlink.roswire.node import RosNode

    payload = imu_payload()
    with RosNode("imu_pub", "/bench_bot", domain_id=DOMAIN, config=client_config(endpoint)) as node:
        from fleetlink.schemas.typestore import load_typestore

        node.typestore = load_typestore("jazzy")
        pub = node.create_publisher(topic, IMU, congestion="block" if mode == "flood" else None)
        deadline = time.monotonic() + 10
        while not pub.matching and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.5)  # let both subscribers' declarations settle at the router
        started = time.monotonic()
        if mode == "flood":
            for _ in range(count):
                pub.publish_cdr(payload)
        else:
            period = 1.0 / rate
            n = int(seconds * rate)
            for i in range(n):
                due = started + i * period
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                pub.publish_cdr(payload)
        elapsed = time.monotonic() - started
        time.sleep(0.5)  # let the last samples leave before the session closes
    print(json.dumps({"published": pub.seq, "seconds": elapsed}), flush=True)


class Recorder:
    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.reset()

    def reset(self) -> None:
        self.first_ns = 0
        self.last_ns = 0
        self.count = 0
        self.latencies: list[int] = []
        self.max_seq = 0

    def add(self, now_ns: int, source_ns: int, seq: int) -> None:
        with self.lock:
            if self.count == 0:
                self.first_ns = now_ns
            self.last_ns = now_ns
            self.count += 1
            self.latencies.append(now_ns - source_ns)
            self.max_seq = max(self.max_seq, seq)

    def report(self) -> dict[str, Any]:
        with self.lock:
            span = (self.last_ns - self.first_ns) / 1e9
            lat = sorted(self.latencies)
            out = {
                "received": self.count,
                "lost": max(0, self.max_seq - self.count) if self.count else 0,
                "samples_per_s": self.count / span if span > 0 else 0.0,
                "p50_ms": lat[len(lat) // 2] / 1e6 if lat else None,
                "p99_ms": lat[min(len(lat) - 1, int(len(lat) * 0.99))] / 1e6 if lat else None,
                "mean_ms": statistics.fmean(lat) / 1e6 if lat else None,
            }
            self.reset()
            return out


def run_subscriber(endpoint: str, kind: str) -> None:
    import zenoh

    rec = Recorder()
    if kind == "raw":
        session = zenoh.open(client_config(endpoint))
        unpack = struct.Struct("<qq").unpack_from

        def on_raw(sample: zenoh.Sample) -> None:
            att = sample.attachment
            if att is None:
                return
            seq, source_ns = unpack(att.to_bytes())
            _ = sample.payload.to_bytes()
            rec.add(time.time_ns(), source_ns, seq)

        subs: list[Any] = [
            session.declare_subscriber(f"{DOMAIN}/bench_bot/{name}/**", on_raw)
            for name in ("imu_raw", "imu_both")
        ]
        closer: Any = session
    else:
        from fleetlink.roswire.node import RosNode
        from fleetlink.roswire.subscriber import RosSample
        from fleetlink.schemas.typestore import load_typestore

        node = RosNode(
            "imu_sub", domain_id=DOMAIN, config=client_config(endpoint), typestore=load_typestore("jazzy")
        ).start()

        def on_ros(sample: RosSample) -> None:
            _ = sample.message.linear_acceleration.z  # decoded by the subscriber (decode=True)
            rec.add(time.time_ns(), sample.source_ts_ns or 0, sample.seq or 0)

        subs = [
            node.create_subscriber(topic, IMU, on_ros, decode=True)
            for topic in ("/bench_bot/imu_roswire", LATENCY_TOPIC)
        ]
        closer = node
    print("ready", flush=True)
    for line in sys.stdin:
        if line.strip() == "report":
            result = rec.report()
            if kind == "roswire":
                result["rejected"] = sum(sub.stats.rejected for sub in subs)
            print(json.dumps(result), flush=True)
        elif line.strip() == "quit":
            break
    if kind == "raw":
        for sub in subs:
            sub.undeclare()
        closer.close()
    else:
        closer.stop()


# --- orchestration --------------------------------------------------------------------------


def child(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, __file__, *args], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT
    )


def read_json(proc: subprocess.Popen[str]) -> dict[str, Any]:
    assert proc.stdout is not None
    line = proc.stdout.readline()
    if not line:
        raise RuntimeError(f"child {proc.args!r} exited without output")
    result: dict[str, Any] = json.loads(line)
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--role", choices=["publisher", "subscriber"])
    parser.add_argument("--endpoint")
    parser.add_argument("--kind", choices=["raw", "roswire"])
    parser.add_argument("--topic", default=LATENCY_TOPIC)
    parser.add_argument("--mode", choices=["flood", "paced"], default="flood")
    parser.add_argument("--count", type=int, default=100_000, help="samples in the throughput phase")
    parser.add_argument("--rate", type=float, default=1000.0, help="Hz in the latency phase")
    parser.add_argument("--seconds", type=float, default=5.0, help="length of the latency phase")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    if args.role == "publisher":
        run_publisher(args.endpoint, args.topic, args.mode, args.count, args.rate, args.seconds)
        return 0
    if args.role == "subscriber":
        run_subscriber(args.endpoint, args.kind)
        return 0

    from fleetlink.localstack.zenoh_router import ZenohRouter

    results: dict[str, Any] = {"payload_bytes": len(imu_payload())}
    with ZenohRouter() as router:
        subs = {
            kind: child("--role", "subscriber", "--endpoint", router.endpoint, "--kind", kind)
            for kind in ("roswire", "raw")
        }
        for proc in subs.values():
            assert proc.stdout is not None
            if proc.stdout.readline().strip() != "ready":
                raise RuntimeError("subscriber did not start")
        phases = [
            (
                "throughput",
                "roswire",
                ["--topic", "/bench_bot/imu_roswire", "--mode", "flood", "--count", str(args.count)],
            ),
            (
                "throughput",
                "raw",
                ["--topic", "/bench_bot/imu_raw", "--mode", "flood", "--count", str(args.count)],
            ),
            ("latency", None, ["--mode", "paced", "--rate", str(args.rate), "--seconds", str(args.seconds)]),
        ]
        for phase, only, extra in phases:
            pub = child("--role", "publisher", "--endpoint", router.endpoint, *extra)
            published = read_json(pub)
            pub.wait(timeout=120)
            time.sleep(1.0)  # drain
            for kind, proc in subs.items():
                assert proc.stdin is not None
                proc.stdin.write("report\n")
                proc.stdin.flush()
                report = read_json(proc)
                if only in (None, kind):
                    report["lost"] = published["published"] - report["received"]
                    report["publisher"] = published
                    results.setdefault(phase, {})[kind] = report
        for proc in subs.values():
            assert proc.stdin is not None
            proc.stdin.write("quit\n")
            proc.stdin.flush()
            proc.wait(timeout=30)
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    thr, lat = results["throughput"], results["latency"]
    print(f"Imu CDR payload {results['payload_bytes']} B; all sessions in client mode through one router")
    print(f"throughput ({args.count} samples, publisher blocks on back-pressure):")
    for kind in ("roswire", "raw"):
        r = thr[kind]
        print(
            f"  {kind:<8} received {r['received']:>7}  lost {r['lost']:>5}  "
            f"{r['samples_per_s']:>9,.0f} samples/s"
        )
    print(f"latency at {args.rate:g} Hz for {args.seconds:g} s, both subscribers at once:")
    for kind in ("roswire", "raw"):
        r = lat[kind]
        print(
            f"  {kind:<8} received {r['received']:>7}  lost {r['lost']:>5}  "
            f"p50 {r['p50_ms']:.3f} ms  p99 {r['p99_ms']:.3f} ms"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
