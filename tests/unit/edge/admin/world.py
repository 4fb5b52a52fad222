"""A small edge for the admin tests: a config, a live mapping table, a ROS graph built from real
rmw_zenoh liveliness tokens (pure ``roswire.graph.Graph``), and a service on top. No sockets."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fleetlink.edge.admin.backend import EdgeSnapshot
from fleetlink.edge.admin.service import AdminService
from fleetlink.edge.admin.store import OverlayStore
from fleetlink.edge.admin.table_backend import TableBackend
from fleetlink.edge.config import EdgeConfig
from fleetlink.edge.mapping import MappingTable
from fleetlink.roswire.graph import Graph, TopicInfo
from fleetlink.roswire.qos import DEFAULT
from fleetlink.roswire.tokens import EntityKind, endpoint_token

HASH = "RIHS01_" + "ab" * 32
IR = "irobot_create_msgs/msg/IrIntensityVector"
IMU = "sensor_msgs/msg/Imu"
BATTERY = "sensor_msgs/msg/BatteryState"


def base_data(spool: str = "/tmp/fleetlink-admin-test/spool") -> dict[str, Any]:
    return {
        "site": "warehouse-a",
        "edge_id": "edge-1",
        "spool": {"dir": spool},
        "robot_types": {
            "tb4": {
                "match": "/tb4_*",
                "mappings": [
                    {
                        "name": "ir",
                        "from": "/{robot}/ir_intensity",
                        "to": "fleet.ir",
                        "type": IR,
                        "stages": [{"type": "throttle", "hz": 5}],
                    },
                    {
                        "name": "odom_1s",
                        "from": "/{robot}/odom",
                        "to": "fleet.odom_1s",
                        "stages": [
                            {
                                "type": "aggregate",
                                "window": "1s",
                                "fields": ["twist.twist.linear.x"],
                                "ops": ["mean"],
                            }
                        ],
                    },
                ],
            }
        },
        "mappings": [{"name": "battery", "from": "/{robot}/battery_state", "to": "fleet.battery"}],
    }


def base_config(spool: str = "/tmp/fleetlink-admin-test/spool") -> EdgeConfig:
    return EdgeConfig.model_validate(base_data(spool))


def publisher(robot: str, topic: str, typename: str, eid: int) -> str:
    return endpoint_token(
        domain=0,
        zid=robot.encode().hex()[:32],
        nid=0,
        eid=eid,
        kind=EntityKind.PUBLISHER,
        namespace=f"/{robot}",
        node_name="create3",
        topic=f"/{robot}/{topic}",
        typename=typename,
        type_hash=HASH,
        qos=DEFAULT,
    )


@dataclass
class FakeGraph:
    graph: Graph = field(default_factory=lambda: Graph(domain=0))

    def publish(self, robot: str, topic: str, typename: str) -> None:
        self.graph.put(publisher(robot, topic, typename, len(self.graph) + 1))

    def topics(self) -> dict[str, TopicInfo]:
        return self.graph.topics()


def fleet_graph() -> FakeGraph:
    """tb4_01 and tb4_02 publishing ir_intensity, imu, battery_state; kb_01 publishing imu."""
    graph = FakeGraph()
    for robot in ("tb4_01", "tb4_02"):
        graph.publish(robot, "ir_intensity", IR)
        graph.publish(robot, "imu", IMU)
        graph.publish(robot, "battery_state", BATTERY)
    graph.publish("kb_01", "imu", IMU)
    return graph


@dataclass
class World:
    config: EdgeConfig
    table: MappingTable
    graph: FakeGraph
    backend: TableBackend
    service: AdminService
    snapshot: list[EdgeSnapshot]


def world(store: Path | None = None, *, snapshot: EdgeSnapshot | None = None) -> World:
    config = base_config()
    table = config.mapping_table()
    table.add_robot("tb4_01")
    graph = fleet_graph()
    current = [snapshot or EdgeSnapshot()]
    backend = TableBackend(table, graph, snapshot=lambda: current[0])
    overlay_store = OverlayStore(store) if store is not None else None
    overlay = overlay_store.load() if overlay_store is not None else None
    service = AdminService(config, backend, overlay=overlay, store=overlay_store)
    return World(config, table, graph, backend, service, current)
