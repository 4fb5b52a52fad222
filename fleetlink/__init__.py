"""fleetlink: connect fleets of ROS 2 robots to Apache Kafka.

This package holds what belongs to no single component: the ``fleetlink`` command line,
configuration-file loading, Zenoh session options and the local test stack.
"""

__version__ = "0.1.0"
