"""The mapping engine: ROS topic patterns -> Kafka topics and keys (pure, no I/O).

    table = MappingTable(robot_types=[...], mappings=[...])
    table.add_robot("tb4_01")                 # type from the robot types' ``match`` globs
    for bound in table.match("/tb4_01/imu"):  # every mapping the topic feeds
        topic = bound.kafka_topic or bound.render_topic(decoded_message)
        key = bound.key or bound.render_key(decoded_message)

Pattern syntax: ``edge.mapping.patterns``; template syntax (Kafka topic rules: ``common.names``):
``edge.mapping.templates``; validation: ``edge.mapping.spec``; the live table:
``edge.mapping.table``. ``edge.config.EdgeConfig.mapping_table()`` builds a table from the YAML.
"""

from fleetlink.edge.mapping.patterns import Capture, TopicPattern, check_robot_name
from fleetlink.edge.mapping.spec import (
    DELIVERIES,
    CompiledMapping,
    Delivery,
    MappingSpec,
    RobotTypeSpec,
    check_name,
    check_ros_type,
    check_unique_names,
    compile_mapping,
)
from fleetlink.edge.mapping.table import BoundMapping, MappingInfo, MappingTable
from fleetlink.edge.mapping.templates import Template

__all__ = [
    "DELIVERIES",
    "BoundMapping",
    "Capture",
    "CompiledMapping",
    "Delivery",
    "MappingInfo",
    "MappingSpec",
    "MappingTable",
    "RobotTypeSpec",
    "Template",
    "TopicPattern",
    "check_name",
    "check_robot_name",
    "check_ros_type",
    "check_unique_names",
    "compile_mapping",
]
