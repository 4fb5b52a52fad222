"""Commands through the production router templates: mTLS on the WAN and per-site ACLs.

The cloud router (deploy/zenoh/cloud-router.json5, ACL for site-a and site-b), one edge router
per site (deploy/zenoh/edge-router.json5, TLS link to the cloud with the site's certificate),
the uplink as a TLS client with the ``fleetlink-uplink`` certificate, a repeater and robots on
each site network. The command path must fit the ACLs: queries from the cloud on
``fleetlink/<site>/command/…`` (and on ``fleetlink/*/command/…`` for a robot of unknown site,
answered by each site under its own key), status queries from the sites on their own prefix.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fleetlink.common.certs import UPLINK_NAME
from fleetlink.repeater.config import RepeaterConfig
from fleetlink.repeater.service import Repeater
from fleetlink.roswire.sim.fleet import Fleet
from tests.helpers import wait_until
from tests.integration.test_commands_harness import (
    RED,
    YELLOW,
    CommandProducer,
    LedLog,
    TopicLog,
    command_keys,
    create_topics,
    irobot_store,
    lightring_mapping,
    running_uplink,
    uid,
    uplink_config,
)
from tests.integration.test_commands_harness import robot_config as site_client
from tests.integration.zenoh_topology import make_bundle, tls_cloud, tls_edge
from tests.paths import IROBOT


def repeater_at(site: str, endpoint: str, state: Path) -> RepeaterConfig:
    return RepeaterConfig.model_validate(
        {
            "repeater": {
                "site": site,
                "state_dir": str(state),
                "id": f"rep-{site}",
                "heartbeat": "300ms",
                "status_timeout": "1s",
                "command_keys": [str(command_keys()[1])],
            },
            "ros": {"distro": "jazzy", "message_paths": [str(IROBOT)]},
            "zenoh": {"mode": "client", "connect": [endpoint]},
        }
    )


def test_commands_cross_the_production_acls(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    ts = irobot_store()
    run = uid()
    topic = f"cmd.lightring.{run}"
    bundle = make_bundle(tmp_path / "certs")
    identity = bundle[UPLINK_NAME]
    tls: dict[str, Any] = {
        "transport/link/tls/root_ca_certificate": str(bundle.ca_certificate),
        "transport/link/tls/enable_mtls": True,
        "transport/link/tls/connect_certificate": str(identity.certificate),
        "transport/link/tls/connect_private_key": str(identity.key),
    }
    producer = CommandProducer(kafka_bootstrap, schema_registry_url, ts)
    leds = LedLog()
    with (
        tls_cloud(bundle) as cloud,
        tls_edge(bundle, "site-a", cloud.endpoint) as edge_a,
        tls_edge(bundle, "site-b", cloud.endpoint) as edge_b,
    ):
        config = uplink_config(
            kafka_bootstrap,
            schema_registry_url,
            cloud.endpoint,
            [lightring_mapping(topic, lease="20s")],
            suffix=run,
        )
        config = config.model_copy(update={"zenoh": config.zenoh.model_copy(update={"overrides": tls})})
        create_topics(kafka_bootstrap, topic, config.topics.registrations)
        with (
            Repeater(repeater_at("site-a", edge_a.endpoint, tmp_path / "a")) as rep_a,
            Repeater(repeater_at("site-b", edge_b.endpoint, tmp_path / "b")) as rep_b,
            Fleet(site_client(edge_b.endpoint), ts, robots=0, rate=1.0, on_led=leds) as robots_b,
            TopicLog(kafka_bootstrap, schema_registry_url, config.topics.command_status) as status,
            running_uplink(config) as uplink,
        ):
            router = uplink.commands
            assert router is not None
            robots_b.add_robot("tb4_07")
            wait_until(
                lambda: rep_b.subscribers("/tb4_07/cmd_lightring") > 0,
                timeout=10,
                message="site-b repeater sees the robot",
            )
            assert rep_a.subscribers("/tb4_07/cmd_lightring") == 0  # raw ROS stays on its site

            # unknown site: a query to every site; each answers under its own prefix
            producer.send(topic, "tb4_07", RED, command_id=f"any-{run}")
            wait_until(lambda: leds.first("tb4_07", "red") is not None, timeout=10, message="red at site-b")
            wait_until(
                lambda: rep_a.stats.applied == 1 and rep_b.stats.applied == 1,
                timeout=10,
                message="both sites applied the command for a robot of unknown site",
            )
            wait_until(lambda: router.stats.settled == 1, timeout=10, message="the uplink got the answers")
            wait_until(
                lambda: any(
                    v["command_id"] == f"any-{run}" and v["status"] == "delivered" and v["site"] == "site-b"
                    for v in status.values()
                ),
                timeout=10,
                message="delivered status crossed the WAN",
            )

            # once registered at site-b, only site-b gets its commands
            producer.register(config.topics.registrations, "tb4_07", "site-b")
            wait_until(
                lambda: router.directory.site_of("tb4_07") == "site-b",
                timeout=10,
                message="registration read",
            )
            producer.send(topic, "tb4_07", YELLOW, command_id=f"b-{run}")
            wait_until(
                lambda: leds.first("tb4_07", "yellow") is not None, timeout=10, message="yellow at site-b"
            )
            wait_until(lambda: rep_b.stats.applied == 2, timeout=5, message="site-b applied it")
            assert rep_a.stats.applied == 1
            assert router.stats.dead_lettered == 0
