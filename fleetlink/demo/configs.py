"""The configs the demo runs with: one site, one uplink, one repeater (pure: dicts in, dicts out)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

SITE = "warehouse-a"
IR_TOPIC = "fleet.ir_intensity"
HAZARD_TOPIC = "fleet.hazard_detection"
KIDNAP_TOPIC = "fleet.kidnap_status"
COMMAND_TOPIC = "fleet.commands.lightring"
REGISTRATIONS_TOPIC = "fleetlink.robots"
STATUS_TOPIC = "fleetlink.commands.status"
SENSOR_TOPICS = (IR_TOPIC, HAZARD_TOPIC, KIDNAP_TOPIC)


@dataclass(frozen=True)
class DemoPlaces:
    """Where the demo's processes meet: Kafka, registry, the two Zenoh routers, its folder."""

    bootstrap: str
    registry_url: str
    cloud_router: str
    site_router: str
    workdir: Path
    msg_paths: tuple[Path, ...]
    edge_admin: str = "127.0.0.1:8480"
    """The edge's admin API: its site console (/console/), /metrics and /health."""
    uplink_metrics: str = "127.0.0.1:9464"
    fleet_console: str = "127.0.0.1:8490"

    @property
    def keys(self) -> Path:
        """The command signing key pair (written by the runner before the configs are used)."""
        return self.workdir / "keys"


def edge_config(p: DemoPlaces) -> dict[str, Any]:
    """The edge's config: TurtleBot 4 IR, hazard and kidnap mappings, a blocking spool, the site router."""
    return {
        "site": SITE,
        "edge_id": "edge-1",
        "ros": {"distro": "jazzy", "message_paths": [str(m) for m in p.msg_paths]},
        "zenoh": {"mode": "client", "connect": [p.site_router]},
        "robot_types": {
            "turtlebot4": {
                "match": "/tb4_*",
                "mappings": [
                    {
                        "name": "ir",
                        "from": "/{robot}/ir_intensity",
                        "to": IR_TOPIC,
                        "type": "irobot_create_msgs/msg/IrIntensityVector",
                    },
                    {
                        "name": "hazards",
                        "from": "/{robot}/hazard_detection",
                        "to": HAZARD_TOPIC,
                        "type": "irobot_create_msgs/msg/HazardDetectionVector",
                    },
                    {
                        "name": "kidnap",
                        "from": "/{robot}/kidnap_status",
                        "to": KIDNAP_TOPIC,
                        "type": "irobot_create_msgs/msg/KidnapStatus",
                    },
                ],
            }
        },
        "registration": {"grace_period": "3s"},
        "spool": {"dir": str(p.workdir / "spool"), "max_bytes": "256MiB", "policy": "block"},
        "wan": {"linger": "20ms", "ack_timeout": "10s"},
        "admin": {"listen": p.edge_admin},
    }


def uplink_config(p: DemoPlaces) -> dict[str, Any]:
    """The uplink's config: Kafka, the registry, the signed light-ring command, metrics and console."""
    return {
        "kafka": {"bootstrap_servers": p.bootstrap, "linger": "2ms"},
        "registry": {"url": p.registry_url},
        "zenoh": {"mode": "client", "connect": [p.cloud_router]},
        "command_signing": {"key_file": str(p.keys / "command-signing-key.pem")},
        "commands": [
            {
                "name": "lightring",
                "from": COMMAND_TOPIC,
                "to": "/{key}/cmd_lightring",
                "type": "irobot_create_msgs/msg/LightringLeds",
                "repeat": {"period": "1s", "lease": "15s"},
            },
        ],
        "metrics": {"listen": p.uplink_metrics},
        "console": {"listen": p.fleet_console},
    }


def repeater_config(p: DemoPlaces) -> dict[str, Any]:
    """The repeater's config: the site, its state folder, the command public key and the site router."""
    return {
        "repeater": {
            "site": SITE,
            "state_dir": str(p.workdir / "repeater"),
            "command_keys": [str(p.keys / "command-signing.pem")],
        },
        "ros": {"distro": "jazzy", "message_paths": [str(m) for m in p.msg_paths]},
        "zenoh": {"mode": "client", "connect": [p.site_router]},
    }
