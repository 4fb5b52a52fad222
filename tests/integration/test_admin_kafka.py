"""End to end through the admin API: a mapping added at runtime to a running edge makes records land
in Kafka (site router -> edge -> WAN -> cloud router -> uplink -> Kafka); removed, they stop."""

from __future__ import annotations

import uuid
from pathlib import Path

import httpx
from confluent_kafka import Consumer, TopicPartition
from pydantic import SecretStr

from fleetlink.console.edge import console_extension
from fleetlink.edge.admin import EdgeAdmin
from fleetlink.edge.agent import EdgeAgent
from fleetlink.schemas.bundled import bundled_message_paths
from tests.helpers import wait_until
from tests.integration.e2e_stack import (
    TopicReader,
    cloud,
    edge_config,
    headers,
    site,
    unique_site,
    wait_spooled_and_acked,
)
from tests.integration.test_admin_api import AUTH, TOKEN, fleet, next_domain


def end_offset(bootstrap: str, topic: str) -> int:
    consumer = Consumer({"bootstrap.servers": bootstrap, "group.id": f"offsets-{uuid.uuid4().hex}"})
    try:
        _low, high = consumer.get_watermark_offsets(TopicPartition(topic, 0), timeout=10)
        return int(high)
    finally:
        consumer.close()


def test_runtime_mapping_reaches_kafka_and_stops(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    topic = f"fleet.ir.admin.{uuid.uuid4().hex[:8]}"
    domain = next_domain()
    with cloud(kafka_bootstrap, schema_registry_url) as cloud_, site(cloud_) as router:
        config = edge_config(
            tmp_path / "spool",
            router.endpoint,
            cloud_,
            site=unique_site(),
            robot_types={"tb4": {"match": "/tb4_*", "mappings": []}},
            ros={"domain_id": domain, "message_paths": [str(p) for p in bundled_message_paths()]},
        )
        admin = EdgeAdmin(
            config,
            token=SecretStr(TOKEN),
            listen="127.0.0.1:0",
            extensions=[console_extension(SecretStr(TOKEN), config.edge_id)],
        )
        with fleet(router.endpoint, domain, rate=10) as sim, EdgeAgent(admin.load()) as agent:
            admin.attach(agent)
            http = httpx.Client(base_url=admin.url, headers=AUTH, timeout=10)
            try:
                wait_until(
                    lambda: sorted(agent.robots()) == ["tb4_01", "tb4_02"], 10, message="robots registered"
                )
                created = http.post(
                    "/mappings",
                    json={
                        "name": "ir_rt",
                        "robot_type": "tb4",
                        "from": "/{robot}/ir_intensity",
                        "to": topic,
                        "type": "irobot_create_msgs/msg/IrIntensityVector",
                        "stages": [{"type": "throttle", "hz": 2}],
                    },
                )
                assert created.status_code == 201, created.text
                reader = TopicReader(kafka_bootstrap, schema_registry_url)
                msgs = reader.read(topic, 4, timeout=30)
                assert {(m.key() or b"").decode() for m in msgs} <= {"tb4_01", "tb4_02"}
                assert {headers(m)["fleetlink.mapping"] for m in msgs} == {"ir_rt"}
                value = reader.value(msgs[0])
                assert isinstance(value["readings"], list)

                assert http.delete("/mappings/ir_rt").status_code == 200
                wait_until(lambda: not agent.subscribed_topics(), 5, message="no subscription left")
                emitted = agent.snapshot()["mappings"]["ir_rt"]["emitted"]
                wait_spooled_and_acked(agent, emitted, timeout=30)
                landed = end_offset(kafka_bootstrap, topic)
                published = sim.published["ir_intensity"]
                wait_until(
                    lambda: sim.published["ir_intensity"] >= published + 20,
                    10,
                    message="the robots keep publishing",
                )
                wait_spooled_and_acked(agent, emitted, timeout=10)
                assert end_offset(kafka_bootstrap, topic) == landed
                assert agent.snapshot()["mappings"]["ir_rt"]["emitted"] == emitted
            finally:
                http.close()
                admin.stop()
