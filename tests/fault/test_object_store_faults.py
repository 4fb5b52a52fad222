"""The object store of claim checks fails under a running edge (docs/guarantees.md, rows 47-49).

s3proxy is a real S3 API server process. Row 47: it is killed (SIGKILL) while a camera publishes;
the records wait at the edge for their objects, nothing reaches Kafka without its object, and
once the store is back every image arrives once, in order, its object readable and matching the
SHA-256 its record states. Row 48: the store refuses (its bucket is gone); the records become
dead letters carrying the image and the store's answer, and the next image after the bucket is
back flows. Row 49: an edge whose credentials the store refuses does not start, naming
``objects``.
"""

from __future__ import annotations

import hashlib
import shutil
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from fleetlink.common.objects import ObjectStore
from fleetlink.edge.agent import EdgeAgent
from fleetlink.edge.runtime.errors import RuntimeSetupError
from fleetlink.localstack.objects import ObjectStoreServer, local_object_store
from tests.helpers import wait_until
from tests.integration.e2e_stack import Cloud, TopicReader, cloud, edge_config, headers, site, unique_site
from tests.integration.test_e2e_images import camera_mapping, camera_robot
from tests.unit.edge.runtime.camera import image_cdr


@pytest.fixture(scope="module")
def cloud_(kafka_bootstrap: str, schema_registry_url: str) -> Iterator[Cloud]:
    with cloud(kafka_bootstrap, schema_registry_url) as c:
        yield c


@pytest.fixture(scope="module")
def reader(kafka_bootstrap: str, schema_registry_url: str) -> TopicReader:
    return TopicReader(kafka_bootstrap, schema_registry_url)


@pytest.fixture
def store(tmp_path: Path) -> Iterator[ObjectStoreServer]:
    server = local_object_store(tmp_path / "s3")
    server.start()
    try:
        yield server
    finally:
        server.stop()


def claims(agent: EdgeAgent) -> dict[str, int]:
    return dict(agent.snapshot()["claims"])


def test_row47_store_killed_records_wait_for_their_objects_and_all_arrive_once(
    cloud_: Cloud, reader: TopicReader, store: ObjectStoreServer, tmp_path: Path
) -> None:
    topic = f"fleet.images.{uuid.uuid4().hex[:8]}"
    with site(cloud_) as router:
        config = edge_config(
            tmp_path / "spool",
            router.endpoint,
            cloud_,
            site=unique_site(),
            robot_types={"cam": {"match": "/cam_*", "mappings": [camera_mapping(topic, above="0")]}},
            objects=store.config_data(retry_backoff_max="500ms", request_timeout="2s"),
        )
        with EdgeAgent(config) as agent, camera_robot(router.endpoint, "cam_11") as camera:
            for seed in range(2):
                camera.publish_cdr(image_cdr(320, 240, seed=seed))
            wait_until(lambda: claims(agent)["claimed"] == 2, 20, message="2 images stored")
            store.kill()
            for seed in range(2, 5):
                camera.publish_cdr(image_cdr(320, 240, seed=seed))

            def failing(objects: dict[str, int]) -> bool:  # the 3 images taken, their uploads failing
                return objects["pending"] == 3 and objects["retries"] >= 2

            wait_until(lambda: failing(agent.snapshot()["objects"]), 20, message="3 uploads failing")
            snap = agent.snapshot()
            assert snap["objects"]["pending"] == 3  # still waiting, neither dropped nor dead-lettered
            assert snap["objects"]["outages"] == 1
            assert claims(agent) == {"inline": 0, "claimed": 2, "failed": 0}
            assert len(reader.read(topic, 2)) == 2  # the 2 stored, then none without its object
            store.start()  # the same port and folder
            wait_until(lambda: claims(agent)["claimed"] == 5, 30, message="all 5 images stored")
            wait_until(lambda: agent.snapshot()["streams"]["durable"]["buffer"]["depth"] == 0, 20)
            assert agent.snapshot()["objects"]["pending"] == 0

    records = reader.read(topic, 5)
    assert [headers(m)["fleetlink.seq"] for m in records] == ["1", "2", "3", "4", "5"]  # once, in order
    with ObjectStore(store.section()) as s3:
        for message in records:
            ref = reader.value(message)["data_ref"]
            data, _ = s3.get(ref["key"])
            assert hashlib.sha256(data).hexdigest() == ref["sha256"]
            assert len(data) == ref["size"]


def test_row48_store_refusing_dead_letters_with_the_image_and_the_next_flows(
    cloud_: Cloud, reader: TopicReader, store: ObjectStoreServer, tmp_path: Path
) -> None:
    topic = f"fleet.images.{uuid.uuid4().hex[:8]}"
    site_name = unique_site()
    bucket_dir = store.settings.data_dir / "blobs" / store.settings.bucket
    with site(cloud_) as router:
        config = edge_config(
            tmp_path / "spool",
            router.endpoint,
            cloud_,
            site=site_name,
            robot_types={"cam": {"match": "/cam_*", "mappings": [camera_mapping(topic, above="0")]}},
            objects=store.config_data(),
        )
        with EdgeAgent(config) as agent, camera_robot(router.endpoint, "cam_12") as camera:
            shutil.rmtree(bucket_dir)  # the store now answers 404 NoSuchBucket: a refusal
            camera.publish_cdr(image_cdr(320, 240, seed=1))
            try:
                wait_until(lambda: claims(agent)["failed"] == 1, 20, message="the refusal")
            except AssertionError as exc:  # say where the image stopped: intake, claims, store
                snap = agent.snapshot()
                seen = {k: snap.get(k) for k in ("intake", "subscriptions", "claims", "objects")}
                raise AssertionError(f"{exc}; the edge: {seen}") from None
            with ObjectStore(store.section()) as s3:
                s3.ensure_bucket()
            camera.publish_cdr(image_cdr(320, 240, seed=2))
            wait_until(lambda: claims(agent)["claimed"] == 1, 20, message="the next image stored")
            wait_until(lambda: agent.snapshot()["streams"]["durable"]["buffer"]["depth"] == 0, 20)
            assert agent.snapshot()["objects"]["refused"] == 1
            assert agent.snapshot()["objects"]["retries"] == 0  # a refusal is not tried again

    [flowed] = reader.read(topic, 1)
    assert headers(flowed)["fleetlink.seq"] == "2"
    assert reader.value(flowed)["data_ref"]["content_type"] == "image/jpeg"
    dead = reader.read_until(
        cloud_.dead_letter, lambda ms: any(headers(m).get("fleetlink.site") == site_name for m in ms)
    )
    [mine] = [m for m in dead if headers(m).get("fleetlink.site") == site_name]
    h = headers(mine)
    assert h["fleetlink.dlq.stage"] == "claim_check"
    assert "HTTP 404" in h["fleetlink.dlq.reason"]
    assert h["fleetlink.dlq.topic"] == topic
    assert h["fleetlink.seq"] == "1"
    value = mine.value()
    assert value is not None
    assert value[:2] == b"\xff\xd8"  # the JPEG itself: nothing of the image is lost
    assert h["fleetlink.dlq.size"] == str(len(value))


def test_row49_refused_credentials_stop_the_start_naming_objects(
    cloud_: Cloud, store: ObjectStoreServer, tmp_path: Path
) -> None:
    config = edge_config(
        tmp_path / "spool",
        cloud_.router,
        cloud_,
        site=unique_site(),
        robot_types={"cam": {"match": "/cam_*", "mappings": [camera_mapping("fleet.images.x")]}},
        objects=store.config_data(secret_access_key="not-the-key"),
    )
    agent = EdgeAgent(config)
    with pytest.raises(RuntimeSetupError, match=r"^objects: .*HTTP 403"):
        agent.start()
    agent.stop()
