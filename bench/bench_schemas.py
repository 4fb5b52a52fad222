"""CDR -> Avro throughput: fleetlink's generated converter next to the two naive paths.

For sensor_msgs/Imu, nav_msgs/Odometry, sensor_msgs/LaserScan (720 ranges + 720 intensities)
and a 640x480 rgb8 sensor_msgs/Image, measured in the same run on one core:

* ``fleetlink``: ``get_codec(...).cdr_to_avro(cdr)`` (generated per-type code);
* ``fastavro``: the original system's path, rosbags ``deserialize_cdr`` -> dict ->
  ``fastavro.schemaless_writer`` with the same schema;
* ``json``: rosbags ``deserialize_cdr`` -> dict -> ``json.dumps``.

Each figure is the best of ``--repeat`` timed runs of at least ``--seconds`` each. Encoded sizes
are per message. Run: ``.venv/bin/python bench/bench_schemas.py``.
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import fastavro
import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys.store import Typestore

from fleetlink.schemas.codec import Codec, get_codec
from fleetlink.schemas.typestore import load_typestore

BYTES_KINDS = ("uint8", "byte", "char")


def to_dict(ts: Typestore, obj: Any, typename: str, *, json_safe: bool) -> dict[str, Any]:
    """The generic walk a hand-written bridge does: rosbags object -> plain dict."""
    out: dict[str, Any] = {}
    for name, desc in ts.fielddefs[typename][1]:
        value = getattr(obj, name)
        if desc[0] == Nodetype.NAME:
            out[name] = to_dict(ts, value, desc[1], json_safe=json_safe)
        elif desc[0] == Nodetype.BASE:
            out[name] = value
        else:
            inner = desc[1][0]
            if inner[0] == Nodetype.NAME:
                out[name] = [to_dict(ts, v, inner[1], json_safe=json_safe) for v in value]
            elif inner[1][0] in BYTES_KINDS and not json_safe:
                out[name] = bytes(value)
            elif isinstance(value, np.ndarray):
                out[name] = value.tolist()
            else:
                out[name] = list(value)
    return out


def messages(ts: Typestore) -> dict[str, bytes]:
    rng = np.random.default_rng(7)
    t = ts.types
    stamp = t["builtin_interfaces/msg/Time"](1_700_000_000, 123_456_789)

    def header(frame: str) -> Any:
        return t["std_msgs/msg/Header"](stamp, frame)

    def vec() -> Any:
        return t["geometry_msgs/msg/Vector3"](*rng.normal(size=3).tolist())

    quat = t["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.3826834, 0.9238795)
    cov9, cov36 = rng.random(9), rng.random(36)
    imu = t["sensor_msgs/msg/Imu"](header("imu_link"), quat, cov9, vec(), cov9, vec(), cov9)
    point = t["geometry_msgs/msg/Point"](1.5, -2.25, 0.0)
    pose = t["geometry_msgs/msg/PoseWithCovariance"](t["geometry_msgs/msg/Pose"](point, quat), cov36)
    twist = t["geometry_msgs/msg/TwistWithCovariance"](t["geometry_msgs/msg/Twist"](vec(), vec()), cov36)
    odom = t["nav_msgs/msg/Odometry"](header("odom"), "base_link", pose, twist)
    scan = t["sensor_msgs/msg/LaserScan"](
        header("laser"), -3.1415927, 3.1415927, 0.0087266, 0.0, 0.1, 0.1, 30.0,
        rng.uniform(0.1, 30.0, 720).astype(np.float32), rng.uniform(0, 255, 720).astype(np.float32),
    )  # fmt: skip
    image = t["sensor_msgs/msg/Image"](
        header("camera"), 480, 640, "rgb8", 0, 640 * 3, rng.integers(0, 256, 640 * 480 * 3, dtype=np.uint8)
    )
    found = {
        "sensor_msgs/msg/Imu": imu,
        "nav_msgs/msg/Odometry": odom,
        "sensor_msgs/msg/LaserScan": scan,
        "sensor_msgs/msg/Image": image,
    }
    return {name: bytes(ts.serialize_cdr(msg, name)) for name, msg in found.items()}


def rate(func: Callable[[], object], seconds: float, repeat: int) -> float:
    """Best calls per second over ``repeat`` runs of at least ``seconds`` each."""
    best = 0.0
    for _ in range(repeat):
        calls, start = 0, time.perf_counter()
        batch = 1
        while True:
            for _ in range(batch):
                func()
            calls += batch
            elapsed = time.perf_counter() - start
            if elapsed >= seconds:
                break
            batch = min(batch * 2, 4096)
        best = max(best, calls / elapsed)
    return best


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=0.4, help="minimum duration of one timed run")
    parser.add_argument("--repeat", type=int, default=3, help="timed runs per figure (best is kept)")
    args = parser.parse_args(argv)

    ts = load_typestore("jazzy")
    header = (
        f"{'type':<26}{'CDR B':>8}{'Avro B':>8}{'JSON B':>9}"
        f"{'fleetlink/s':>13}{'fastavro/s':>12}{'json/s':>10}{'x fastavro':>11}{'x json':>8}"
    )
    print(header)
    print("-" * len(header))
    for typename, cdr in messages(ts).items():
        codec = get_codec(ts, typename, "jazzy")
        parsed = codec.parsed_schema

        def ours(cdr: bytes = cdr, codec: Codec = codec) -> bytes:
            return codec.cdr_to_avro(cdr)

        def naive(cdr: bytes = cdr, typename: str = typename, parsed: Any = parsed) -> bytes:
            out = io.BytesIO()
            datum = to_dict(ts, ts.deserialize_cdr(cdr, typename), typename, json_safe=False)
            fastavro.schemaless_writer(out, parsed, datum)
            return out.getvalue()

        def as_json(cdr: bytes = cdr, typename: str = typename) -> bytes:
            return json.dumps(
                to_dict(ts, ts.deserialize_cdr(cdr, typename), typename, json_safe=True)
            ).encode()

        avro = ours()
        if naive() != avro:
            print(f"{typename}: the two Avro paths disagree", file=sys.stderr)
            return 1
        fast, slow, text = (rate(f, args.seconds, args.repeat) for f in (ours, naive, as_json))
        print(
            f"{typename.split('/')[-1]:<26}{len(cdr):>8}{len(avro):>8}{len(as_json()):>9}"
            f"{fast:>13,.0f}{slow:>12,.0f}{text:>10,.0f}{fast / slow:>10.1f}x{fast / text:>7.1f}x"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
