"""The robot page's latest values over a real Zenoh router: a camera's picture comes as a data: URL.

A robot publishes its camera as rmw_zenoh does (a raw 250x250 rgb8 ``sensor_msgs/msg/Image``, the
simulator's picture, and a ``CompressedImage``); the console's ``LatestValues`` reads each topic
once and answers its picture, which the page shows as an ``<img>``.
"""

from __future__ import annotations

import base64
import io
import itertools
import threading
from collections.abc import Iterator

import numpy as np
import pytest
from PIL import Image
from rosbags.typesys.store import Typestore

from fleetlink.console.latest import LatestValues
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.sim.messages import MessageFactory
from fleetlink.schemas.typestore import load_typestore
from tests.helpers import zenoh_peer_config

_domains = itertools.count(231)


@pytest.fixture(scope="module")
def typestore() -> Typestore:
    return load_typestore("jazzy")


@pytest.fixture
def camera(zenoh_router: str, typestore: Typestore) -> Iterator[int]:
    """A robot publishing its raw camera and a compressed copy at 10 Hz; yields its domain."""
    domain = next(_domains)
    stop = threading.Event()
    out = io.BytesIO()
    Image.new("RGB", (32, 24), (0, 0, 255)).save(out, format="PNG")
    messages = MessageFactory(typestore, "tb4_07")
    with RosNode(
        "camera", "/tb4_07", domain_id=domain, config=zenoh_peer_config(zenoh_router), typestore=typestore
    ) as node:
        raw = node.create_publisher("oakd/rgb/preview/image_raw", "sensor_msgs/msg/Image")
        small = node.create_publisher("oakd/rgb/compressed", "sensor_msgs/msg/CompressedImage")
        compressed = typestore.types["sensor_msgs/msg/CompressedImage"](
            header=messages.header(0.0, "cam"), format="png", data=np.frombuffer(out.getvalue(), np.uint8)
        )

        def publish() -> None:
            number = 0
            while not stop.wait(0.1):
                number += 1
                raw.publish(messages.camera_image(0.0, number))
                small.publish(compressed)

        thread = threading.Thread(target=publish, daemon=True)
        thread.start()
        try:
            yield domain
        finally:
            stop.set()
            thread.join(5)


def test_a_cameras_latest_picture_is_answered_for_the_page(
    zenoh_router: str, typestore: Typestore, camera: int
) -> None:
    import zenoh

    with zenoh.open(zenoh_peer_config(zenoh_router)) as session:
        latest = LatestValues(lambda: session, camera, typestore.deserialize_cdr, wait_s=5.0)
        values = latest.read(["/tb4_07/oakd/rgb/preview/image_raw", "/tb4_07/oakd/rgb/compressed"])
    raw = values["/tb4_07/oakd/rgb/preview/image_raw"]
    assert raw["type"] == "sensor_msgs/msg/Image"
    assert raw["picture"].startswith("data:image/jpeg;base64,")
    shown = Image.open(io.BytesIO(base64.b64decode(raw["picture"].split(",", 1)[1])))
    assert shown.size == (250, 250)
    small = values["/tb4_07/oakd/rgb/compressed"]
    assert small["picture"].startswith("data:image/png;base64,")
    assert Image.open(io.BytesIO(base64.b64decode(small["picture"].split(",", 1)[1]))).size == (32, 24)
