"""sensor_msgs/Image samples for the record maker's tests (CDR made by rosbags)."""

from __future__ import annotations

from functools import cache

import numpy as np

from fleetlink.roswire.subscriber import RosSample
from fleetlink.schemas.typestore import load_typestore

IMAGE = "sensor_msgs/msg/Image"
IMAGE_HASH = "RIHS01_" + "1a" * 32
STAMP_NS = 1_700_000_000_123_456_789


@cache
def _ts():  # type: ignore[no-untyped-def]
    return load_typestore("jazzy")


def frame(width: int, height: int, seed: int = 0) -> np.ndarray:
    """A camera-like frame: a gradient with noise (JPEG makes it some 20x smaller)."""
    y, x = np.mgrid[0:height, 0:width]
    base = np.stack([x * 255 // width, y * 255 // height, (x + y) % 256], -1)
    noise = np.random.default_rng(seed).integers(0, 8, base.shape)
    return (base + noise).clip(0, 255).astype(np.uint8)


def image_cdr(width: int = 64, height: int = 48, *, seed: int = 0, encoding: str = "rgb8") -> bytes:
    ts = _ts()
    t = ts.types
    pixels = frame(width, height, seed)
    msg = t[IMAGE](
        header=t["std_msgs/msg/Header"](
            stamp=t["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="cam"
        ),
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0,
        step=width * 3,
        data=pixels.reshape(-1),
    )
    return bytes(ts.serialize_cdr(msg, IMAGE))


def image_sample(topic: str, payload: bytes, *, seq: int = 1) -> RosSample:
    return RosSample(
        topic=topic,
        typename=IMAGE,
        type_hash=IMAGE_HASH,
        payload=payload,
        seq=seq,
        source_ts_ns=STAMP_NS + seq,
        gid=b"\x02" * 16,
        key=f"0{topic}/sensor_msgs::msg::dds_::Image_/{IMAGE_HASH}",
        received_ns=STAMP_NS + 5_000_000,
    )
