"""fleetlink: connect fleets of ROS 2 robots to Apache Kafka.

One installed name, in layers that only point down (docs/architecture.md)::

    fleetlink.common                         errors, durations, config base, names, metrics, Zenoh options
    fleetlink.wire, fleetlink.schemas        the edge/uplink/repeater wire contract; ROS types <-> Avro
    fleetlink.roswire                        ROS 2 over Zenoh (rmw_zenoh), without ROS 2
    fleetlink.edge | uplink | repeater       the three services (never importing each other)
    fleetlink.console                        the web console, served by the services' processes
    fleetlink.localstack, fleetlink.examples the local test stack; the demo's stream-processing app
    fleetlink.demo, fleetlink.cli            the warehouse demo; the ``fleetlink`` command
"""

__version__ = "0.1.0"
