"""sensor_msgs/Image pixels -> JPEG or PNG bytes, and the CompressedImage ``format`` text (pure).

``Image.data`` holds ``height`` rows of ``step`` bytes; a row holds ``width`` pixels of the
encoding's size and may be padded. The pixels are viewed with numpy (no copy but for BGR -> RGB
and padded rows) and encoded with Pillow (libjpeg-turbo, zlib). The ``format`` text follows
``compressed_image_transport`` so that ROS tools decode the result as they decode a camera's
own compressed topic: ``"<encoding>; jpeg compressed bgr8"`` for colour (the decoder's output
order; the file itself is a standard JPEG/PNG), ``"mono8; jpeg compressed mono8"`` for grey.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

ImageFormat = Literal["jpeg", "png"]


class ImageError(ValueError):
    """One image cannot be compressed (unknown encoding, data shorter than its size, ...)."""


@dataclass(frozen=True, slots=True)
class Encoding:
    """How an image encoding lays out a pixel: channels, bytes per channel, channel order."""

    channels: int
    depth: int
    """Bytes per channel."""
    reverse: bool = False
    """Channels in BGR(A) order."""


ENCODINGS: dict[str, Encoding] = {
    "rgb8": Encoding(3, 1),
    "bgr8": Encoding(3, 1, reverse=True),
    "rgba8": Encoding(4, 1),
    "bgra8": Encoding(4, 1, reverse=True),
    "mono8": Encoding(1, 1),
    "8UC1": Encoding(1, 1),
    "8UC3": Encoding(3, 1, reverse=True),  # OpenCV's order, as cv_bridge reads it
    "8UC4": Encoding(4, 1, reverse=True),
    "mono16": Encoding(1, 2),
    "16UC1": Encoding(1, 2),
}
"""The encodings compressed (``sensor_msgs/image_encodings.hpp`` names)."""

CONTENT_TYPES: dict[ImageFormat, str] = {"jpeg": "image/jpeg", "png": "image/png"}


def pixels(value: Any) -> tuple[np.ndarray, Encoding]:
    """The image's pixels as an array (height, width[, channels]) and its encoding."""
    name = str(value["encoding"])
    encoding = ENCODINGS.get(name)
    if encoding is None:
        raise ImageError(f"encoding {name!r} is not compressed (known: {', '.join(ENCODINGS)})")
    height, width, step = int(value["height"]), int(value["width"]), int(value["step"])
    row = width * encoding.channels * encoding.depth
    if height <= 0 or width <= 0:
        raise ImageError(f"image of {width}x{height} pixels")
    if step < row:
        raise ImageError(f"step {step} is shorter than a row of {width} {name} pixels ({row} bytes)")
    data = value["data"]
    buffer = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data.view(np.uint8)
    if buffer.size < height * step:
        raise ImageError(f"data holds {buffer.size} bytes, {height} rows of {step} need {height * step}")
    rows = buffer[: height * step].reshape(height, step)[:, :row]
    if encoding.depth == 2:
        big = bool(value.get("is_bigendian", 0))
        array = np.ascontiguousarray(rows).view(">u2" if big else "<u2").reshape(height, width)
        return array.astype("<u2", copy=False), encoding
    shape = (height, width) if encoding.channels == 1 else (height, width, encoding.channels)
    array = rows.reshape(shape)
    if encoding.reverse:
        array = array[..., [2, 1, 0, 3][: encoding.channels]]
    return array, encoding


def compress(value: Any, fmt: ImageFormat, *, quality: int = 80, level: int = 1) -> tuple[bytes, str]:
    """(the compressed bytes, the CompressedImage ``format`` text) of one Image message."""
    from PIL import Image  # the images extra: checked when the stage is built

    array, encoding = pixels(value)
    source = str(value["encoding"])
    if encoding.depth == 2:
        if fmt == "jpeg":
            raise ImageError(f"{source} has 16-bit pixels: JPEG takes 8 bits (use format: png)")
        picture = Image.fromarray(np.ascontiguousarray(array, dtype="<u2"))  # mode I;16
        target = "mono16"
    elif encoding.channels == 1:
        picture = Image.fromarray(np.ascontiguousarray(array))  # mode L
        target = "mono8"
    else:
        picture = Image.fromarray(np.ascontiguousarray(array[..., :3]))  # mode RGB
        target = "bgr8"
    out = io.BytesIO()
    if fmt == "jpeg":
        picture.save(out, format="JPEG", quality=quality)
    else:
        picture.save(out, format="PNG", compress_level=level)
    return out.getvalue(), f"{source}; {fmt} compressed {target}"


def content_type_of(format_text: str) -> str:
    """The MIME type of a CompressedImage whose ``format`` is ``format_text`` (``jpeg``, ``png``,
    ``rgb8; jpeg compressed bgr8`` ...); ``application/octet-stream`` when it names neither."""
    text = format_text.lower()
    if "jpeg" in text or "jpg" in text:
        return CONTENT_TYPES["jpeg"]
    if "png" in text:
        return CONTENT_TYPES["png"]
    return "application/octet-stream"
