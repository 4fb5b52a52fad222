"""``compress_image``: sensor_msgs/Image in, sensor_msgs/CompressedImage out (JPEG or PNG).

The output is exactly what a ROS camera's ``compressed`` topic carries, so the Kafka records
have the CompressedImage schema (``fleetlink schemas avro sensor_msgs/msg/CompressedImage``)
and every consumer of compressed camera images reads them: ``header`` as received, ``format``
as ``compressed_image_transport`` writes it, ``data`` the JPEG or PNG file. Pillow does the
encoding (the ``images`` extra). An image that cannot be compressed (an encoding outside
``images.ENCODINGS``, data shorter than its rows, 16-bit pixels for JPEG) is counted in
``errors`` and dropped, with the reason in ``last_error``.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

from fleetlink.common.extras import missing_extra
from fleetlink.edge.stages.base import Sample, StageCounters
from fleetlink.edge.stages.errors import StageConfigError
from fleetlink.edge.stages.images import ImageError, ImageFormat, compress
from fleetlink.schemas.avro_schema import avro_fullname, avro_schema
from fleetlink.schemas.typehash import HUMBLE_HASH
from fleetlink.schemas.typestore import Distro, load_typestore

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"


@functools.cache
def compressed_image_schema(humble: bool = False) -> dict[str, Any]:
    """CompressedImage's Avro schema as fleetlink generates it for any distro (the message did not
    change from Humble on; only Humble has no type hash)."""
    distro: Distro = "humble" if humble else "jazzy"
    return avro_schema(load_typestore(distro), COMPRESSED_IMAGE, distro)


def _check_pillow() -> None:
    try:
        import PIL.Image  # noqa: F401 - only whether it is there
    except ModuleNotFoundError as exc:
        raise StageConfigError(f"compress_image: {missing_extra(exc, 'images')}") from None


class CompressImageStage:
    """Compresses sensor_msgs/Image samples to sensor_msgs/CompressedImage (JPEG with ``quality``, or PNG
    with zlib ``level``)."""

    def __init__(
        self, fmt: ImageFormat = "jpeg", *, quality: int = 80, level: int = 1, name: str = "compress_image"
    ) -> None:
        _check_pillow()
        self.name = name
        self.format: ImageFormat = fmt
        self.quality = quality
        self.level = level
        self.counters = StageCounters()
        self.last_error: str | None = None

    def process(self, sample: Sample, now_ns: int) -> list[Sample]:  # noqa: ARG002 - stateless
        """The sample's image compressed, as a CompressedImage value with the same header; an image that
        cannot be compressed is counted as an error and dropped."""
        counters = self.counters
        counters.received += 1
        value = sample.value
        try:
            data, format_text = compress(value, self.format, quality=self.quality, level=self.level)
        except (ImageError, KeyError, TypeError, ValueError, OSError) as exc:
            counters.errors += 1
            self.last_error = f"{type(exc).__name__}: {exc}"
            return []
        counters.passed += 1
        counters.emitted += 1
        out = {"header": value["header"], "format": format_text, "data": data}
        # replace keeps what the caller's sample type carries besides (the edge: its sequence number)
        return [dataclasses.replace(sample, value=out, raw=None)]

    def tick(self, now_ns: int) -> list[Sample]:  # noqa: ARG002 - nothing is time-driven here
        """Nothing: the stage holds no samples."""
        return []

    def output_schema(self, input_schema: dict[str, Any]) -> dict[str, Any]:
        """The CompressedImage schema of the input's ROS distro; raises ``StageConfigError`` unless the
        input is sensor_msgs/Image."""
        name = input_schema.get("name", "")
        namespace = input_schema.get("namespace")
        full = name if "." in name or not namespace else f"{namespace}.{name}"
        if full != avro_fullname(IMAGE):
            raise StageConfigError(f"compress_image takes {IMAGE} messages, not {full or 'this type'}")
        return compressed_image_schema(input_schema.get("ros_type_hash") == HUMBLE_HASH)
