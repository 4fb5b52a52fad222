"""Camera images end to end: how many MB/s of 921 KB images reach Kafka.

    .venv/bin/python bench/bench_images.py [--images 300] [--modes raw,jpeg] [--rate 0]

Starts Kafka + Apicurio (or uses $KAFKA_BOOTSTRAP / $SCHEMA_REGISTRY_URL) and, as separate
processes, the uplink (cloud router) and the edge agent (site router, durable spool); for the
``jpeg`` mode also s3proxy (the object store). A robot in this process publishes
sensor_msgs/Image, 640x480 rgb8 (921,600 bytes of pixels, a camera-like gradient with noise),
reliable and blocking; a consumer reads the Kafka topic. Modes:

* ``raw``: the Image as it is, one 921.7 KB Kafka record each;
* ``jpeg``: ``compress_image`` (JPEG, quality 80) and ``claim_check`` (every JPEG to s3proxy, the
  record carries the reference).

Prints per mode: images delivered of published, seconds from the first publish to the last
record read, MB/s of camera pixels (921,600 bytes an image) and images/s, the CPU seconds of
the edge and the uplink. ``--rate`` (images/s, 0: as fast as the robot can publish) offers a
steady rate instead of a burst: the figure is sustained when delivered = published and the
elapsed time is the publishing time plus a fraction of a second.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.bench_e2e import create_topic, read_topic, tree_cpu  # noqa: E402
from fleetlink.common.zenoh_options import ZenohOptions  # noqa: E402
from fleetlink.localstack.objects import local_object_store  # noqa: E402
from fleetlink.localstack.process import ServerProcess, alive, exit_on_sigterm, free_port, log_tail  # noqa: E402
from fleetlink.localstack.stack import LocalStack  # noqa: E402
from fleetlink.roswire.node import RosNode  # noqa: E402
from fleetlink.roswire.qos import History, QoS  # noqa: E402
from fleetlink.roswire.session import ros_session_config  # noqa: E402
from fleetlink.schemas.typestore import load_typestore  # noqa: E402
from tests.unit.edge.runtime.camera import IMAGE, image_cdr  # noqa: E402

PIXELS = 640 * 480 * 3


def start(work: Path, name: str, config: dict[str, Any], argv: list[str], stack: ExitStack) -> ServerProcess:
    path = work / f"{name}.yaml"
    path.write_text(yaml.safe_dump(config))
    log = work / f"{name}.log"
    marker = work / f"{name}.ready"
    extra = ["--stats-file", str(marker)] if name == "edge" else []

    def uplink_up() -> bool:
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
    return proc


def run_mode(mode: str, work: Path, bootstrap: str, registry: str, images: int, rate: float) -> str:
    work.mkdir(parents=True)
    topic = create_topic(bootstrap, f"bench.images.{mode}")
    mapping: dict[str, Any] = {"name": "camera", "from": "/{robot}/image_raw", "to": topic}
    with ExitStack() as stack:
        edge_extra: dict[str, Any] = {}
        if mode == "jpeg":
            store = local_object_store(work / "s3")
            store.start()
            stack.callback(store.stop)
            edge_extra["objects"] = store.config_data()
            mapping["stages"] = [{"type": "compress_image", "format": "jpeg", "quality": 80}]
            mapping["claim_check"] = {"above": "0"}
        cloud_port, site_port = free_port(), free_port()  # after the store took its port
        uplink = {
            "kafka": {"bootstrap_servers": bootstrap, "linger": "5ms", "compression": "none"},
            "registry": {"url": registry},
            "zenoh": {"mode": "router", "listen": [f"tcp/127.0.0.1:{cloud_port}"]},
        }
        edge = {
            "site": "bench",
            "edge_id": "edge-1",
            "zenoh": {
                "mode": "router",
                "listen": [f"tcp/127.0.0.1:{site_port}"],
                "connect": [f"tcp/127.0.0.1:{cloud_port}"],
            },
            "robot_types": {"cam": {"match": "/cam*", "mappings": [mapping]}},
            "spool": {"dir": str(work / "spool"), "max_bytes": "4GiB", "segment_bytes": "64MiB"},
            "intake": {"max_bytes": "256MiB"},
            "wan": {"linger": "5ms", "max_in_flight": 4, "codec": "none", "batch_max_bytes": "8MiB"},
            **edge_extra,
        }
        procs = {
            "uplink": start(work, "uplink", uplink, ["uplink", "run"], stack),
            "edge": start(work, "edge", edge, ["edge", "run"], stack),
        }
        frames = [image_cdr(640, 480, seed=i) for i in range(8)]
        for name, proc in procs.items():
            if proc.pid is None or not alive(proc.pid):
                raise SystemExit(f"the {name} stopped:\n{log_tail(work / f'{name}.log')}")
        node = RosNode(
            "camera",
            "/cam01",
            config=ros_session_config(ZenohOptions(mode="client", connect=(f"tcp/127.0.0.1:{site_port}",))),
            typestore=load_typestore("jazzy"),
        ).start()
        stack.callback(node.stop)
        publisher = node.create_publisher("/cam01/image_raw", IMAGE, QoS(history=History.KEEP_ALL, depth=100))
        deadline = time.monotonic() + 20
        while not publisher.has_subscribers():
            if time.monotonic() > deadline:
                raise SystemExit("the edge did not subscribe within 20 s")
            time.sleep(0.05)
        time.sleep(2.0)  # the robot registered, the subscription settled
        got: list[tuple[float, int]] = []
        reader = threading.Thread(
            target=lambda: got.extend(
                read_topic(bootstrap, topic, images, 120 + images / 5, per_record=False)
            )
        )
        reader.start()
        cpu0 = {name: tree_cpu(p.pid) for name, p in procs.items() if p.pid}
        began = time.time()
        interval = 1.0 / rate if rate > 0 else 0.0
        for i in range(images):
            if interval:
                delay = began + i * interval - time.time()
                if delay > 0:
                    time.sleep(delay)
            publisher.publish_cdr(frames[i % len(frames)])
        published_s = time.time() - began
        reader.join()
        cpu = {name: tree_cpu(p.pid) - cpu0[name] for name, p in procs.items() if p.pid}
    if not got:
        return f"{mode}: nothing delivered"
    elapsed = max(t for t, _ in got) - began
    mb_s = len(got) * PIXELS / elapsed / 1e6
    return (
        f"{mode}: {len(got)}/{images} images in {elapsed:.2f} s (published in {published_s:.2f} s) = "
        f"{mb_s:.1f} MB/s of camera pixels, {len(got) / elapsed:.1f} images/s; CPU s: "
        + ", ".join(f"{k} {v:.1f}" for k, v in cpu.items())
    )


def main() -> None:
    exit_on_sigterm()
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--images", type=int, default=300)
    ap.add_argument("--modes", default="raw,jpeg")
    ap.add_argument("--rate", type=float, default=0.0, help="images/s offered (0: as fast as possible)")
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    with ExitStack() as stack, tempfile.TemporaryDirectory(prefix="fleetlink-bench-images-") as tmp:
        work = Path(tmp)
        bootstrap, registry = os.environ.get("KAFKA_BOOTSTRAP"), os.environ.get("SCHEMA_REGISTRY_URL")
        if not (bootstrap and registry):
            local = LocalStack(work / "stack")
            info = local.start()
            stack.callback(local.stop)
            bootstrap, registry = info.bootstrap, info.registry_url
        print(f"640x480 rgb8 images ({PIXELS:,} bytes of pixels); {os.cpu_count()} CPUs", flush=True)
        for round_ in range(args.repeat):
            for mode in args.modes.split(","):
                line = run_mode(mode, work / f"{mode}{round_}", bootstrap, registry, args.images, args.rate)
                print(f"  round {round_ + 1}, {line}", flush=True)


if __name__ == "__main__":
    main()
