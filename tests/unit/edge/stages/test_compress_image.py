"""The compress_image stage: every encoding it takes, the format text, its schema and its errors."""

from __future__ import annotations

import io
import sys
from typing import Any

import fastavro
import numpy as np
import pytest
from PIL import Image
from pydantic import TypeAdapter, ValidationError

from fleetlink.edge.stages import CompressImageStage, Sample, StageConfigError, StageSpec, build_pipeline
from fleetlink.edge.stages.compress_image import compressed_image_schema
from fleetlink.edge.stages.images import ENCODINGS, content_type_of, pixels
from fleetlink.schemas.avro_schema import avro_schema
from fleetlink.schemas.typestore import load_typestore

HEADER = {"stamp": {"sec": 7, "nanosec": 5}, "frame_id": "camera"}
H, W = 48, 64


def rgb() -> np.ndarray:
    y, x = np.mgrid[0:H, 0:W]
    return np.stack([x * 4, y * 5, (x + y) * 2], -1).astype(np.uint8)


def image(encoding: str, pixels_: np.ndarray, *, pad: int = 0, big: bool = False) -> dict[str, Any]:
    rows = pixels_.reshape(H, -1)
    if rows.dtype != np.uint8:
        rows = rows.astype(">u2" if big else "<u2").view(np.uint8).reshape(H, -1)
    padded = np.concatenate([rows, np.full((H, pad), 0xEE, np.uint8)], axis=1) if pad else rows
    return {
        "header": HEADER,
        "height": H,
        "width": W,
        "encoding": encoding,
        "is_bigendian": int(big),
        "step": padded.shape[1],
        "data": padded.tobytes(),
    }


def run(stage: CompressImageStage, value: dict[str, Any]) -> list[Sample]:
    return stage.process(Sample("r1", "/r1/camera/image_raw", 1, value, b"cdr"), 0)


def decoded(out: Sample) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(out.value["data"])))


@pytest.mark.parametrize(
    ("encoding", "make", "expect", "target"),
    [
        ("rgb8", lambda p: p, lambda p: p, "bgr8"),
        ("bgr8", lambda p: p[..., ::-1], lambda p: p, "bgr8"),
        ("8UC3", lambda p: p[..., ::-1], lambda p: p, "bgr8"),
        ("rgba8", lambda p: np.dstack([p, np.full((H, W), 9, np.uint8)]), lambda p: p, "bgr8"),
        ("bgra8", lambda p: np.dstack([p[..., ::-1], np.full((H, W), 9, np.uint8)]), lambda p: p, "bgr8"),
        ("mono8", lambda p: p[..., 1], lambda p: p[..., 1], "mono8"),
        ("8UC1", lambda p: p[..., 0], lambda p: p[..., 0], "mono8"),
    ],
)
@pytest.mark.parametrize("pad", [0, 5])
def test_png_keeps_every_pixel(encoding: str, make: Any, expect: Any, target: str, pad: int) -> None:
    stage = CompressImageStage("png")
    (out,) = run(stage, image(encoding, make(rgb()), pad=pad))
    assert out.value["format"] == f"{encoding}; png compressed {target}"
    assert out.value["header"] == HEADER
    assert out.raw is None
    assert np.array_equal(decoded(out), expect(rgb()))
    assert stage.counters.as_dict() == {
        "received": 1,
        "passed": 1,
        "dropped": 0,
        "late": 0,
        "errors": 0,
        "emitted": 1,
        "nan": 0,
    }


@pytest.mark.parametrize("big", [False, True])
def test_sixteen_bit_depth_images_go_to_png(big: bool) -> None:
    depth = (np.arange(H * W).reshape(H, W) * 13 % 65536).astype(np.uint16)
    (out,) = run(CompressImageStage("png"), image("mono16", depth, big=big))
    assert out.value["format"] == "mono16; png compressed mono16"
    assert np.array_equal(decoded(out), depth)
    stage = CompressImageStage("jpeg")
    assert run(stage, image("16UC1", depth)) == []
    assert stage.counters.errors == 1
    assert "JPEG takes 8 bits" in (stage.last_error or "")


def test_jpeg_is_close_and_quality_trades_size() -> None:
    smooth = rgb()
    sizes = []
    for quality in (30, 95):
        (out,) = run(CompressImageStage("jpeg", quality=quality), image("rgb8", smooth))
        assert out.value["format"] == "rgb8; jpeg compressed bgr8"
        assert out.value["data"][:3] == b"\xff\xd8\xff"  # a JPEG file
        error = np.abs(decoded(out).astype(int) - smooth.astype(int)).mean()
        assert error < (6 if quality == 95 else 12)
        sizes.append(len(out.value["data"]))
    assert sizes[0] < sizes[1]


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"encoding": "bayer_rggb8"}, "encoding 'bayer_rggb8' is not compressed"),
        ({"encoding": "32FC1"}, "is not compressed"),
        ({"step": 10}, "step 10 is shorter than a row"),
        ({"data": b"\x00" * 100}, "data holds 100 bytes"),
        ({"height": 0}, "image of 64x0 pixels"),
        ({"encoding": None}, "is not compressed"),
    ],
)
def test_a_bad_image_is_counted_not_raised(change: dict[str, Any], reason: str) -> None:
    stage = CompressImageStage()
    assert run(stage, {**image("rgb8", rgb()), **change}) == []
    assert stage.counters.errors == 1
    assert stage.counters.emitted == 0
    assert reason in (stage.last_error or "")
    (out,) = run(stage, image("rgb8", rgb()))  # the next one flows
    assert out.value["format"].startswith("rgb8;")


def test_output_schema_is_compressed_image_and_fits_the_value() -> None:
    ts = load_typestore("jazzy")
    image_schema = avro_schema(ts, "sensor_msgs/msg/Image", "jazzy")
    stage = CompressImageStage()
    schema = stage.output_schema(image_schema)
    assert schema == avro_schema(ts, "sensor_msgs/msg/CompressedImage", "jazzy")
    (out,) = run(stage, image("rgb8", rgb()))
    buf = io.BytesIO()
    fastavro.schemaless_writer(buf, fastavro.parse_schema(schema), out.value)
    buf.seek(0)
    assert fastavro.schemaless_reader(buf, fastavro.parse_schema(schema)) == out.value
    humble = avro_schema(load_typestore("humble"), "sensor_msgs/msg/Image", "humble")
    assert stage.output_schema(humble) == compressed_image_schema(humble=True)
    assert compressed_image_schema(humble=True)["ros_type_hash"] == "TypeHashNotSupported"


def test_refuses_other_types() -> None:
    ts = load_typestore("jazzy")
    with pytest.raises(
        StageConfigError, match=r"takes sensor_msgs/msg/Image messages, not ros\.sensor_msgs\.msg\.Imu"
    ):
        CompressImageStage().output_schema(avro_schema(ts, "sensor_msgs/msg/Imu", "jazzy"))
    pipeline = build_pipeline(_specs([{"type": "compress_image"}]))
    with pytest.raises(StageConfigError, match=r"stage 0 \(compress_image\): compress_image takes"):
        pipeline.output_schema(avro_schema(ts, "sensor_msgs/msg/CompressedImage", "jazzy"))


def _specs(data: list[dict[str, Any]]) -> list[Any]:
    return TypeAdapter(list[StageSpec]).validate_python(data)


def test_spec_defaults_and_limits() -> None:
    (spec,) = _specs([{"type": "compress_image"}])
    assert (spec.format, spec.quality, spec.level) == ("jpeg", 80, 1)
    for bad in ({"quality": 0}, {"quality": 101}, {"level": 10}, {"format": "webp"}, {"quality": "80"}):
        with pytest.raises(ValidationError):
            _specs([{"type": "compress_image", **bad}])
    pipeline = build_pipeline(_specs([{"type": "compress_image", "format": "png", "level": 6}]))
    stage = pipeline.stages[0]
    assert isinstance(stage, CompressImageStage)
    assert (stage.name, stage.format, stage.level) == ("compress_image", "png", 6)


def test_without_pillow_the_stage_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "PIL.Image", None)
    monkeypatch.setitem(sys.modules, "PIL", None)
    with pytest.raises(StageConfigError, match=r"pip install 'fleetlink\[images\]'"):
        CompressImageStage()


def test_pixels_view_and_content_types() -> None:
    array, encoding = pixels(image("bgr8", rgb()[..., ::-1], pad=3))
    assert encoding == ENCODINGS["bgr8"]
    assert np.array_equal(array, rgb())
    assert content_type_of("rgb8; jpeg compressed bgr8") == "image/jpeg"
    assert content_type_of("png") == "image/png"
    assert content_type_of("JPG") == "image/jpeg"
    assert content_type_of("") == "application/octet-stream"
