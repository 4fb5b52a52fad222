"""The record maker's image and claim-check paths: compress_image, claim jobs, the record limit."""

from __future__ import annotations

import hashlib
import io
from typing import Any

import pytest
from PIL import Image

from fleetlink.edge.claim_check import ClaimCheckSpec, Claimed, ObjectRef
from fleetlink.edge.mapping import MappingSpec
from fleetlink.edge.stages import CompressImageSpec
from fleetlink.wire.limits import kafka_record_bytes
from tests.unit.edge.runtime.camera import STAMP_NS, image_cdr, image_sample
from tests.unit.edge.runtime.test_records import headers, maker_for, read_value

TOPIC = "/cam_1/image_raw"


def camera(**claim: Any) -> MappingSpec:
    return MappingSpec(
        name="camera",
        source="/{robot}/image_raw",
        topic="fleet.images",
        stages=(CompressImageSpec(type="compress_image", format="png"),),
        claim_check=ClaimCheckSpec.model_validate(claim) if claim else None,
    )


def ref_for(job: Any) -> ObjectRef:
    upload = job.upload
    return ObjectRef(
        url=f"http://store/bucket/{upload.key}",
        bucket="bucket",
        key=upload.key,
        size=len(upload.data),
        sha256=upload.sha256,
        content_type=upload.content_type,
    )


def test_compress_image_makes_a_compressed_image_record() -> None:
    maker, _, seen = maker_for([camera()])
    out = maker.make(image_sample(TOPIC, image_cdr(64, 48)), 0)
    assert len(out) == 1
    value = read_value(out[0].record, seen)
    assert value["format"] == "rgb8; png compressed bgr8"
    with Image.open(io.BytesIO(value["data"])) as img:
        assert (img.format, img.size) == ("PNG", (64, 48))
    assert maker.claims == []


def test_a_large_payload_becomes_an_upload_and_its_record_carries_the_reference() -> None:
    maker, _, seen = maker_for([camera(above=100)], object_prefix="p/")
    assert maker.make(image_sample(TOPIC, image_cdr(64, 48)), 0) == []  # waits for its upload
    [job] = maker.drain_claims()
    assert maker.drain_claims() == []
    upload = job.upload
    assert upload is not None
    assert upload.content_type == "image/png"
    assert upload.sha256 == hashlib.sha256(upload.data).hexdigest()
    assert upload.key == f"p/warehouse-a/cam_1/camera/{STAMP_NS + 1}-{upload.sha256}.png"
    out = maker.finish_claim(Claimed(job, ref=ref_for(job)))
    [record] = [o.record for o in out]
    value = read_value(record, seen)
    assert value["data"] == b""
    assert value["data_ref"] == ref_for(job).as_datum()
    assert record.kafka_topic == "fleet.images"
    assert maker.claim_stats.claimed == 1


def test_the_same_image_again_gets_the_same_key() -> None:
    keys = []
    for _ in range(2):
        maker, _, _ = maker_for([camera(above=0)])
        maker.make(image_sample(TOPIC, image_cdr(64, 48)), 0)
        [job] = maker.drain_claims()
        keys.append(job.upload.key if job.upload else None)
    assert keys[0] is not None
    assert keys[0] == keys[1]
    maker, _, _ = maker_for([camera(above=0)])
    maker.make(image_sample(TOPIC, image_cdr(64, 48, seed=1)), 0)  # other bytes, same stamp
    [job] = maker.drain_claims()
    assert job.upload is not None
    assert job.upload.key != keys[0]


def test_a_small_payload_stays_inline_with_a_null_reference() -> None:
    maker, _, seen = maker_for([camera(above=10 << 20)])
    maker.make(image_sample(TOPIC, image_cdr(64, 48)), 0)
    [job] = maker.drain_claims()
    assert job.upload is None
    [out] = maker.finish_claim(Claimed(job))
    value = read_value(out.record, seen)
    assert value["data"][:4] == b"\x89PNG"
    assert value["data_ref"] is None
    assert maker.claim_stats.inline == 1


def test_a_payload_below_the_threshold_still_goes_to_the_store_when_the_record_would_not_fit() -> None:
    maker, _, _ = maker_for([camera(above=10 << 20)], max_record_bytes=2000)
    maker.make(image_sample(TOPIC, image_cdr(64, 48)), 0)
    [job] = maker.drain_claims()
    assert job.upload is not None


def test_a_payload_the_store_did_not_take_becomes_a_dead_letter_with_its_bytes() -> None:
    maker, _, _ = maker_for([camera(above=0)])
    maker.make(image_sample(TOPIC, image_cdr(64, 48)), 0)
    [job] = maker.drain_claims()
    [out] = maker.finish_claim(Claimed(job, error="object store refused the payload: HTTP 403"))
    h = headers(out.record)
    assert out.record.kafka_topic == "fleetlink.dead-letter"
    assert h["fleetlink.dlq.stage"] == "claim_check"
    assert "HTTP 403" in h["fleetlink.dlq.reason"]
    assert job.upload is not None
    assert out.record.value == job.upload.data
    assert maker.claim_stats.failed == 1


def test_claim_check_on_a_field_that_is_not_bytes_is_reported() -> None:
    spec = MappingSpec(
        name="camera",
        source="/{robot}/image_raw",
        topic="fleet.images",
        claim_check=ClaimCheckSpec.model_validate({"field": "encoding"}),
    )
    maker, _, _ = maker_for([spec])
    [out] = maker.make(image_sample(TOPIC, image_cdr(64, 48)), 0)
    assert out.record.kafka_topic == "fleetlink.dead-letter"
    assert "not bytes" in headers(out.record)["fleetlink.dlq.reason"]


@pytest.mark.parametrize("oversize", ["dead_letter", "drop"])
def test_a_record_above_the_uplinks_limit_never_goes(oversize: str) -> None:
    plain = MappingSpec(name="raw", source="/{robot}/image_raw", topic="fleet.raw")
    maker, _, _ = maker_for([plain], oversize=oversize)
    payload = image_cdr(64, 48)
    [ok] = maker.make(image_sample(TOPIC, payload), 0)
    assert ok.record.kafka_topic == "fleet.raw"
    size = kafka_record_bytes(len(ok.record.key or b""), len(ok.record.value) - 5, ok.record.headers)
    maker.set_record_limit(size - 1)  # the uplink said less than this record needs
    out = maker.make(image_sample(TOPIC, payload, seq=2), 0)
    assert maker.oversized == 1
    if oversize == "drop":
        assert out == []
        assert maker.counters["raw"].dropped == 1
        return
    [dead] = out
    h = headers(dead.record)
    assert dead.record.kafka_topic == "fleetlink.dead-letter"
    assert "uplink's Kafka limit" in h["fleetlink.dlq.reason"]
    assert dead.record.value == b""  # no room for it: size and SHA-256 instead
    assert h["fleetlink.dlq.sha256"]
    maker.set_record_limit(size)
    [again] = maker.make(image_sample(TOPIC, payload, seq=3), 0)
    assert again.record.kafka_topic == "fleet.raw"
