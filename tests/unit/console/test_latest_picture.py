"""console.latest.picture_of: a camera's latest picture as a data: URL the robot page shows."""

from __future__ import annotations

import base64
import io
from types import SimpleNamespace

import numpy as np
import pytest
from PIL import Image

from fleetlink.console.latest import MAX_PICTURE_BYTES, picture_of

pytestmark = pytest.mark.unit


def jpeg(width: int = 8, height: int = 6) -> bytes:
    out = io.BytesIO()
    Image.new("RGB", (width, height), (200, 30, 30)).save(out, format="JPEG")
    return out.getvalue()


def test_a_compressed_image_is_shown_as_it_came() -> None:
    data = jpeg()
    url = picture_of(
        "sensor_msgs/msg/CompressedImage", SimpleNamespace(format="jpeg", data=np.frombuffer(data, np.uint8))
    )
    assert url == "data:image/jpeg;base64," + base64.b64encode(data).decode()
    png = picture_of(
        "sensor_msgs/msg/CompressedImage", SimpleNamespace(format="rgb8; png compressed bgr8", data=b"x")
    )
    assert png is not None
    assert png.startswith("data:image/png;base64,")


def test_a_raw_image_is_compressed_to_jpeg() -> None:
    pixels = np.zeros((6, 8, 3), np.uint8)
    pixels[..., 0] = 255  # red, in rgb8
    raw = SimpleNamespace(encoding="rgb8", height=6, width=8, step=24, data=pixels.tobytes(), is_bigendian=0)
    url = picture_of("sensor_msgs/msg/Image", raw)
    assert url is not None
    assert url.startswith("data:image/jpeg;base64,")
    shown = Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1])))
    assert shown.size == (8, 6)
    pixel = shown.convert("RGB").getpixel((4, 3))
    assert isinstance(pixel, tuple)
    red, green, blue = pixel
    assert red > 200
    assert green < 60
    assert blue < 60


@pytest.mark.parametrize(
    ("typename", "message"),
    [
        ("sensor_msgs/msg/Imu", SimpleNamespace(data=b"x")),
        ("sensor_msgs/msg/CompressedImage", SimpleNamespace(format="tiff", data=b"x")),
        (
            "sensor_msgs/msg/CompressedImage",
            SimpleNamespace(format="jpeg", data=b"x" * (MAX_PICTURE_BYTES + 1)),
        ),
        (
            "sensor_msgs/msg/Image",
            SimpleNamespace(encoding="yuv422", height=2, width=2, step=4, data=b"1234" * 2),
        ),
        ("sensor_msgs/msg/Image", SimpleNamespace(encoding="rgb8", height=2, width=2, step=6, data=b"short")),
    ],
)
def test_what_is_no_picture_is_not_shown(typename: str, message: object) -> None:
    assert picture_of(typename, message) is None
