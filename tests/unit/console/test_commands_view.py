"""fleetlink.console.uplink.command_view: the uplink's command router as the console shows it.

The router is built for real (its constructor opens nothing) on stand-ins for the Zenoh
session, the Kafka sink and the registry, none of which is used."""

from __future__ import annotations

from typing import Any, cast

import zenoh
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

from fleetlink.console.uplink import NO_COMMANDS, command_view
from fleetlink.schemas.registry import SchemaRegistry
from fleetlink.uplink.commands.router import CommandRouter
from fleetlink.uplink.commands.signing import CommandSigner
from fleetlink.uplink.config import UplinkConfig
from fleetlink.uplink.producer import KafkaSink


def router() -> CommandRouter:
    config = UplinkConfig.model_validate(
        {
            "kafka": {"bootstrap_servers": "127.0.0.1:9"},
            "registry": {"url": "http://127.0.0.1:9"},
            "command_signing": {"key_file": "unused.pem"},
            "commands": [
                {
                    "name": "lightring",
                    "from": "fleet.commands.lightring",
                    "to": "/{key}/cmd_lightring",
                    "type": "irobot_create_msgs/msg/LightringLeds",
                }
            ],
        }
    )
    unused: Any = object()
    return CommandRouter(
        config,
        session=cast(zenoh.Session, unused),
        sink=cast(KafkaSink, unused),
        registry=cast(SchemaRegistry, unused),
        signer=CommandSigner(Ed25519PrivateKey.generate()),
    )


def test_without_a_router() -> None:
    assert command_view(None) == {"available": False, "reason": NO_COMMANDS}


def test_the_router_counters() -> None:
    r = router()
    r.stats.add(records=5, forwards=4, settled=3, dead_lettered=1, expired_unacknowledged=1)
    r.stats.results["applied"] += 3
    r.directory.apply("tb4_01", {"robot": "tb4_01", "site": "warehouse-a", "event": "registered"})
    r.intake.heartbeats = 7
    view = command_view(r)
    assert view == {
        "available": True,
        "records": 5,
        "forwards": 4,
        "settled": 3,
        "dead_lettered": 1,
        "expired_before_forward": 0,
        "expired_unacknowledged": 1,
        "results": {"applied": 3},
        "in_flight": 0,
        "status_records_written": 0,
        "status_batches": 0,
        "heartbeats": 7,
        "robots_known": 1,
        "sites": ["warehouse-a"],
        "mappings": [{"name": "lightring", "from": "fleet.commands.lightring", "to": "/{key}/cmd_lightring"}],
    }
